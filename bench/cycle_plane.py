"""PyTorch reference for Nuvo's bijectivity losses on a flat square, to check the Rust trainer.

Usage:  python3 bench/cycle_plane.py [--steps 1000] [--lr 3e-3] [--init torch|he|lecun] [--seed 0]

One chart: t: R^3 -> [0,1]^2 (sigmoid) and s: [0,1]^2 -> R^3, 4x128 ReLU MLPs behind a degree-4
positional encoding gamma(pi*z) = [z, sin(2^k pi z), cos(2^k pi z)], k < 4 (as nuvo-core with
encoding_scale = pi), trained on L = cycle_3d + cycle_2d + 10 * surface (symmetric Chamfer) with
Adam and cosine decay, 2048 points of the square z = 0, |x|,|y| <= 1/2 and 2048 UVs per step.
The same problem as `nuvo train` with `[losses.cycle_3d] [losses.cycle_2d] [losses.surface]` on a
flat square mesh. Prints the losses and the fraction of the square whose map is flipped.
"""
import argparse
import math

import torch

L, W, D, B = 4, 128, 4, 2048


def penc(z):
    z = math.pi * z
    return torch.cat([z] + [f(2**k * z) for k in range(L) for f in (torch.sin, torch.cos)], -1)


def mlp(d_in, d_out, init, out_act=None):
    layers, d = [], d_in * (1 + 2 * L)
    for _ in range(D - 1):
        layers += [torch.nn.Linear(d, W), torch.nn.ReLU()]
        d = W
    layers.append(torch.nn.Linear(d, d_out))
    if out_act:
        layers.append(out_act)
    net = torch.nn.Sequential(*layers)
    lins = [m for m in net if isinstance(m, torch.nn.Linear)]
    for k, m in enumerate(lins):
        fan_in, fan_out = m.in_features, m.out_features
        if init == "he":
            bound = math.sqrt(6 / fan_in) if k < len(lins) - 1 else math.sqrt(6 / (fan_in + fan_out))
        elif init == "lecun":
            bound = math.sqrt(3 / fan_in)
        else:
            continue  # PyTorch's default: U(+-1/sqrt(fan_in)) for weights and biases
        torch.nn.init.uniform_(m.weight, -bound, bound)
        torch.nn.init.zeros_(m.bias)
    return net


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--lr", type=float, default=3e-3)
    ap.add_argument("--init", choices=["torch", "he", "lecun"], default="torch")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    torch.manual_seed(a.seed)
    torch.set_num_threads(a.threads)
    t, s = mlp(3, 2, a.init, torch.nn.Sigmoid()), mlp(2, 3, a.init)
    opt = torch.optim.Adam(list(t.parameters()) + list(s.parameters()), lr=a.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, a.steps)
    for it in range(a.steps):
        x = torch.cat([torch.rand(B, 2) - 0.5, torch.zeros(B, 1)], 1)
        u = torch.rand(B, 2)
        c3 = ((s(penc(t(penc(x)) - 0.5)) - x) ** 2).sum(1).mean()
        su = s(penc(u - 0.5))
        c2 = ((t(penc(su)) - u) ** 2).sum(1).mean()
        d = torch.cdist(su, x) ** 2
        surface = d.min(0).values.mean() + d.min(1).values.mean()
        loss = c3 + c2 + 10 * surface
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if (it + 1) % 250 == 0:
            print(f"step {it + 1}: cycle_3d {c3.item():.3e} cycle_2d {c2.item():.3e} surface {surface.item():.3e}")
    with torch.no_grad():
        n = 61
        g = torch.linspace(-0.5, 0.5, n)
        gx, gy = torch.meshgrid(g, g, indexing="ij")
        p = torch.stack([gx.flatten(), gy.flatten(), torch.zeros(n * n)], 1)
        uv = t(penc(p)).reshape(n, n, 2)
        e1, e2 = uv[1:, :-1] - uv[:-1, :-1], uv[:-1, 1:] - uv[:-1, :-1]
        det = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
        flipped = (det < 0).float().mean().item()
        print(f"flipped fraction {min(flipped, 1 - flipped):.3f}")


if __name__ == "__main__":
    main()
