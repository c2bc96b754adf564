"""PyTorch (CPU) reference for `nuvo bench step`: one complete Nuvo training step, timed.

Usage:  python3 bench/torch_step.py [--charts 4] [--depth 8] [--width 256] [--batch 5000]
                                    [--threads 2] [--iters 5] [--mesh assets/stanford-bunny.obj]
                                    [--print-losses]

What it measures: the wall time of one optimisation step of the full Nuvo objective on the bundled
bunny, the median and minimum of `iters` steps after 1 warm-up step (as `nuvo bench step`), and the
process's peak resident memory (ru_maxrss), also as it stood before the first step: importing torch
and building torch.optim.Adam (which loads more of torch lazily) take about 0.7 GB with this torch
build before any work is done. A step is: zero the gradients, draw the batch (area-uniform surface
samples with face normals, random tangent frames, uniform UVs; numpy), every network evaluation,
all eight losses at the paper's default weights, one backward pass, the trainer's NaN guard, and an
Adam step at the cosine-decayed learning rates (schedule over 1000 steps, like the bench config).

How it mirrors the Rust step (nuvo-core/src/trainer.rs, model.rs, losses/src/context.rs, builtin/):
  * model frame: canonical bounding-box frame ([-1, 1]^3, longest half-extent 1) times 0.5;
  * each network sees gamma_L(pi * z), gamma = [z, sin(2^k z), cos(2^k z) for k < L] in blocks of d
    columns (encoding_scale = pi); chart c: degree 1, n logits; texture t_i: degree 4, sigmoid;
    surface s_i: degree 4 on u - 1/2, identity output. `depth` Linear layers, `depth - 1` of them
    `width` wide with ReLU; PyTorch's default init U(+-1/sqrt(fan_in)) (our default `init = "torch"`);
  * sigma (init 1) and one normal grid per chart, round(256 sqrt(2/n)) texels a side, zeros;
  * the same evaluations: c(x); t_i on x, x + eps p and x + eps q stacked in one call; s_i on
    t_i(x) and u (shared by all charts) stacked in one call; t_i(s_i(u)); c on all s_i(u) stacked,
    once (the context's "Evaluations stacked");
  * the same loss formulas, floors and normalisations (cycle_3d, cycle_2d, entropy, surface, cluster,
    conformal, stretch with area = "paper", unsigned, texture with a bilinear lookup, align-corners);
  * Chamfer nearest neighbours from kd-trees (scipy cKDTree, queried with `--threads` workers) built
    each step on the detached points in both directions, then gathered with torch indexing so the
    gradient flows through the chosen pairs, as our kiddo trees do. Note: published PyTorch Nuvo
    reimplementations often use brute-force pairwise distances (torch.cdist + min) instead, which
    costs n*B^2 distances per step (and that much memory) rather than O(n B log B);
  * Adam (beta 0.9/0.999, eps 1e-8, bias-corrected) with per-group rates mlp 1e-4, sigma 0.1,
    grid 0.04 times the cosine factor.

What differs (necessarily): the random streams (numpy/torch seeds, not our ChaCha streams), so the
weights and batches are not bit-identical; the grids are one (n, 3, R, R) tensor sampled with
F.grid_sample instead of n separate R^2 x 3 parameters (same values, same update); scipy builds
float64 trees; autograd keeps its own graph instead of our tape; torch's Adam is its default CPU
(single-tensor) implementation, and the batch is drawn on one thread (ours in parallel). Everything
else is the same formulas in float32.
"""
import argparse
import math
import resource
import time

import numpy as np
import torch
import torch.nn.functional as F
from scipy.spatial import cKDTree

from objio import read_obj

# The paper's default weights (`nuvo losses`).
WEIGHTS = {"cycle_3d": 1.0, "cycle_2d": 1.0, "entropy": 0.04, "surface": 10.0,
           "cluster": 0.5, "conformal": 0.4, "stretch": 0.1, "texture": 0.1}
EPSILON = 1e-2  # training.epsilon: finite-difference step in the model frame
ENCODING_SCALE = math.pi  # model.encoding_scale
STEPS = 1000  # the bench config's training.steps: the cosine schedule's span
LR = {"mlp": 1e-4, "sigma": 0.1, "grid": 0.04}


class Surface:
    """The mesh in the model frame, with its area table and face normals."""

    def __init__(self, path):
        v, f = read_obj(path)
        v = v.astype(np.float32)
        used = v[np.unique(f)]  # bounding box of the referenced vertices (what our loader keeps)
        lo, hi = used.min(0), used.max(0)
        v = (v - 0.5 * (lo + hi)) / (0.5 * (hi - lo)).max() * 0.5  # canonical, then model frame
        a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
        cross = np.cross(b - a, c - a)
        area = 0.5 * np.linalg.norm(cross, axis=1)
        keep = area > 0  # zero-area faces are never sampled
        self.a, self.b, self.c = a[keep], b[keep], c[keep]
        self.normals = (cross[keep] / (2.0 * area[keep, None])).astype(np.float32)
        self.cdf = np.cumsum(area[keep].astype(np.float64))

    def sample(self, rng, n):
        """n area-uniform points with their face normals (inverse-CDF face, square-root warp)."""
        face = np.searchsorted(self.cdf, rng.random(n) * self.cdf[-1], side="right")
        face = np.minimum(face, len(self.cdf) - 1)
        s = np.sqrt(rng.random(n, dtype=np.float32))[:, None]
        r2 = rng.random(n, dtype=np.float32)[:, None]
        b1, b2 = s * (1 - r2), s * r2
        x = (1 - b1 - b2) * self.a[face] + b1 * self.b[face] + b2 * self.c[face]
        return x.astype(np.float32), self.normals[face]


def tangent_frames(rng, normals):
    """Uniformly random orthonormal (p, q = n x p) in each tangent plane (batch.rs)."""
    helper = np.zeros_like(normals)
    use_x = np.abs(normals[:, 0]) < 0.9
    helper[use_x, 0], helper[~use_x, 1] = 1.0, 1.0
    a = helper - (helper * normals).sum(1, keepdims=True) * normals
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(normals, a)
    angle = rng.random(len(normals), dtype=np.float32)[:, None] * np.float32(2 * math.pi)
    p = np.cos(angle) * a + np.sin(angle) * b
    return p.astype(np.float32), np.cross(normals, p).astype(np.float32)


def posenc(z, degree):
    """gamma(z) = [z, sin(2^0 z), cos(2^0 z), ..., sin(2^(L-1) z), cos(2^(L-1) z)], no pi."""
    blocks = [z]
    for k in range(degree):
        blocks += [torch.sin((2.0 ** k) * z), torch.cos((2.0 ** k) * z)]
    return torch.cat(blocks, dim=1)


class EncodedMlp(torch.nn.Module):
    """act_out(MLP(gamma(scale * (z - center)))): `depth` Linear layers, ReLU between them."""

    def __init__(self, d_in, d_out, degree, depth, width, out_act, center=0.0):
        super().__init__()
        self.degree, self.center, self.out_act = degree, center, out_act
        layers, d = [], d_in * (1 + 2 * degree)
        for _ in range(depth - 1):
            layers += [torch.nn.Linear(d, width), torch.nn.ReLU()]
            d = width
        layers.append(torch.nn.Linear(d, d_out))
        self.net = torch.nn.Sequential(*layers)

    def forward(self, z):
        y = self.net(posenc(ENCODING_SCALE * (z - self.center), self.degree))
        return torch.sigmoid(y) if self.out_act == "sigmoid" else y

    def macs_per_row(self):
        return sum(m.in_features * m.out_features for m in self.net if isinstance(m, torch.nn.Linear))


class Nuvo(torch.nn.Module):
    def __init__(self, n, depth, width):
        super().__init__()
        self.chart = EncodedMlp(3, n, 1, depth, width, "identity")
        self.tex = torch.nn.ModuleList(EncodedMlp(3, 2, 4, depth, width, "sigmoid") for _ in range(n))
        self.surf = torch.nn.ModuleList(
            EncodedMlp(2, 3, 4, depth, width, "identity", center=0.5) for _ in range(n))
        self.sigma = torch.nn.Parameter(torch.tensor(1.0))
        res = round(256 * math.sqrt(2 / n))
        # Grid of chart i: grids[i, k, y, x] is channel k of texel (x, y); u indexes x, v indexes y.
        self.grids = torch.nn.Parameter(torch.zeros(n, 3, res, res))


def sq_dist(a, b):
    return (a - b).square().sum(1, keepdim=True)  # B x 1


def losses(model, x, normals, u, tp, tq):
    """The eight unweighted terms, each network evaluated once per input (losses/src/context.rs)."""
    n, B, T = len(model.tex), x.shape[0], u.shape[0]
    c = torch.softmax(model.chart(x), dim=1)  # B x n

    def weighted_mean(per_chart):  # (1/|G|) sum_x sum_i c(x)[i] d_i(x)
        return (torch.cat(per_chart, dim=1) * c).sum() / B

    xp, xq = x + EPSILON * tp, x + EPSILON * tq
    t, dp, dq = [], [], []
    for i in range(n):  # t_i(x) and the finite-difference UV vectors D t_i(eps p), D t_i(eps q)
        ti, tpi, tqi = model.tex[i](torch.cat([x, xp, xq])).split(B)  # one stacked evaluation
        t.append(ti)
        dp.append(tpi - ti)
        dq.append(tqi - ti)
    cyc3, s = [], []
    for i in range(n):  # s_i(t_i(x)) and s_i(u), one stacked evaluation
        back, si = model.surf[i](torch.cat([t[i], u])).split([B, T])
        cyc3.append(back)
        s.append(si)
    cyc2 = [model.tex[i](s[i]) for i in range(n)]
    s_all = torch.cat(s, dim=0)  # n|T| x 3, chart 0 first
    log_c_s = torch.log_softmax(model.chart(s_all), dim=1)  # n|T| x n

    out = {}
    out["cycle_3d"] = weighted_mean([sq_dist(cyc3[i], x) for i in range(n)])
    out["cycle_2d"] = torch.cat([sq_dist(cyc2[i], u) for i in range(n)], dim=1).sum() / T
    own = torch.arange(n).repeat_interleave(T)  # row block i keeps column i
    out["entropy"] = -log_c_s[torch.arange(n * T), own].sum() / T
    # Symmetric Chamfer: kd-trees on this step's detached points, gradient through the pairs.
    s_np, x_np = s_all.detach().numpy(), x.numpy()
    _, near_s = cKDTree(s_np).query(x_np, k=1, workers=torch.get_num_threads())
    _, near_x = cKDTree(x_np).query(s_np, k=1, workers=torch.get_num_threads())
    out["surface"] = (sq_dist(s_all[torch.from_numpy(near_s)], x).mean()
                      + sq_dist(s_all, x[torch.from_numpy(near_x)]).mean())
    mass = c.sum(0)[:, None] + 1e-6  # n x 1, floored
    mu = (c.t() @ x) / mass  # n x 3, gradient flows through the centroids
    out["cluster"] = weighted_mean([sq_dist(x, mu[i:i + 1]) for i in range(n)])
    conf, stretch = [], []
    for a, b in zip(dp, dq):
        dot = (a * b).sum(1, keepdim=True)
        norms = a.square().sum(1, keepdim=True) * b.square().sum(1, keepdim=True) + 1e-20
        conf.append(dot.square() / norms)
        area = (a[:, :1] * b[:, 1:] - a[:, 1:] * b[:, :1]).abs()  # area = "paper" (prop. to eps^2)
        stretch.append((area - model.sigma).square())
    out["conformal"], out["stretch"] = weighted_mean(conf), weighted_mean(stretch)
    # Bilinear lookup N_i(t_i(x)): align_corners (u = 0 and 1 are texel centres), border clamp.
    g = torch.stack(t, dim=0)[:, :, None, :] * 2 - 1  # n x B x 1 x 2, (u, v) -> (x, y) in [-1, 1]
    looked = F.grid_sample(model.grids, g, mode="bilinear", padding_mode="border", align_corners=True)
    looked = looked[:, :, :, 0].permute(0, 2, 1)  # n x B x 3
    out["texture"] = weighted_mean([sq_dist(looked[i], normals) for i in range(n)])
    return out


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--charts", type=int, default=4)
    p.add_argument("--depth", type=int, default=8)
    p.add_argument("--width", type=int, default=256)
    p.add_argument("--batch", type=int, default=5000, help="3-D samples and UV samples each")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--iters", type=int, default=5)
    p.add_argument("--mesh", default="assets/stanford-bunny.obj")
    p.add_argument("--print-losses", action="store_true", help="print the warm-up step's terms")
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    print(f"torch {torch.__version__}, threads {torch.get_num_threads()}")
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    surface = Surface(a.mesh)
    model = Nuvo(a.charts, a.depth, a.width)
    mlp_params = [q for name, q in model.named_parameters() if name not in ("sigma", "grids")]
    opt = torch.optim.Adam([{"params": mlp_params, "lr": LR["mlp"], "base": LR["mlp"]},
                            {"params": [model.sigma], "lr": LR["sigma"], "base": LR["sigma"]},
                            {"params": [model.grids], "lr": LR["grid"], "base": LR["grid"]}],
                           betas=(0.9, 0.999), eps=1e-8)
    step_index = [0]
    setup_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux

    def step():
        opt.zero_grad(set_to_none=False)
        # The batch, drawn inside the step as the Rust trainer does.
        x_np, n_np = surface.sample(rng, a.batch)
        tp_np, tq_np = tangent_frames(rng, n_np)
        u = torch.from_numpy(rng.random((a.batch, 2), dtype=np.float32))
        x, normals = torch.from_numpy(x_np), torch.from_numpy(n_np)
        terms = losses(model, x, normals, u, torch.from_numpy(tp_np), torch.from_numpy(tq_np))
        total = sum(WEIGHTS[k] * v for k, v in terms.items())
        values = {k: v.item() for k, v in terms.items()}  # the trainer logs every term
        factor = 0.5 * (1 + math.cos(math.pi * min(step_index[0] / STEPS, 1.0)))
        if all(math.isfinite(v) for v in values.values()):
            total.backward()
            # The trainer's NaN guard: skip the update if any gradient is not finite.
            if all(bool(torch.isfinite(q.grad).all()) for q in model.parameters()):
                for group in opt.param_groups:
                    group["lr"] = group["base"] * factor
                opt.step()
        step_index[0] += 1
        return total.item(), values

    total, values = step()  # warm-up
    if a.print_losses:
        print("warm-up step terms (unweighted; weight in brackets):")
        for k, v in values.items():
            print(f"  {k:<10} {v:12.6g}  [{WEIGHTS[k]:g}]")
        print(f"  {'total':<10} {total:12.6g}  (weighted sum)   sigma after step {model.sigma.item():.6g}")
    times = []
    for _ in range(max(a.iters, 1)):
        t0 = time.perf_counter()
        step()
        times.append(time.perf_counter() - t0)
    times.sort()
    med, best = times[len(times) // 2], times[0]
    # FLOPs counted as `nuvo bench step` counts them: 3x the forward multiply-adds, times 2.
    n, b = a.charts, a.batch
    c_m, t_m, s_m = model.chart.macs_per_row(), model.tex[0].macs_per_row(), model.surf[0].macs_per_row()
    fwd = 2.0 * (b * (c_m + 3 * n * t_m + n * s_m) + b * n * (s_m + t_m + c_m))
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux
    print(f"torch step n={n} {a.depth}×{a.width} batch {b}+{b}: median {med:.3f} s  min {best:.3f} s  "
          f"~{3 * fwd / 1e9:.0f} GFLOP/step (3× forward)  {3 * fwd / med / 1e9:.1f} GFLOP/s  "
          f"peak RSS {rss_mb:.0f} MB ({setup_kib / 1024.0:.0f} MB before the first step)")


if __name__ == "__main__":
    main()
