"""PyTorch reference for `nuvo bench mlp`: the same MLPs, batch and step on the CPU.

Usage:  python3 bench/torch_mlp.py [--threads 2] [--batch 4096] [--iters 20]

Each case is a ReLU MLP with 27 inputs and 3 outputs (as `nuvo bench`), `depth` fully-connected
layers of `width` channels. A step is forward, mean of squared outputs, backward (the input needs no
gradient). FLOPs are counted exactly as `nuvo bench` counts them, and the timing is the median (and
minimum) of `iters` steps after 3 warm-up steps.
"""
import argparse
import time

import torch


def mlp(depth, width, d_in=27, d_out=3):
    layers, d = [], d_in
    for _ in range(depth - 1):
        layers += [torch.nn.Linear(d, width), torch.nn.ReLU()]
        d = width
    layers.append(torch.nn.Linear(d, d_out))
    return torch.nn.Sequential(*layers)


def macs_per_row(depth, width, d_in=27, d_out=3):
    dims = [d_in] + [width] * (depth - 1) + [d_out]
    return sum(a * b for a, b in zip(dims, dims[1:]))


def bench(depth, width, batch, iters, with_adam):
    torch.manual_seed(0)
    net = mlp(depth, width)
    opt = torch.optim.Adam(net.parameters(), lr=1e-4) if with_adam else None
    x = torch.rand(batch, 27) * 2 - 1

    def step():
        net.zero_grad(set_to_none=False)
        loss = net(x).square().mean()
        loss.backward()
        if opt is not None:
            opt.step()

    for _ in range(3):
        step()
    times = []
    for _ in range(iters):
        t = time.perf_counter()
        step()
        times.append(time.perf_counter() - t)
    times.sort()
    fwd = 2.0 * batch * macs_per_row(depth, width)
    flops = 3.0 * fwd - 2.0 * batch * 27 * width
    med, best = times[len(times) // 2], times[0]
    name = f"torch mlp {depth}x{width} fwd+bwd{'+adam' if with_adam else ''}, batch {batch}"
    print(f"{name:<44} median {med*1e3:8.2f} ms  min {best*1e3:8.2f} ms  "
          f"{flops/med/1e9:6.1f} GFLOP/s (median)  {flops/best/1e9:6.1f} GFLOP/s (best)")


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--batch", type=int, default=4096)
    p.add_argument("--iters", type=int, default=20)
    a = p.parse_args()
    torch.set_num_threads(a.threads)
    print(f"torch {torch.__version__}, threads {torch.get_num_threads()}")
    for depth, width in [(8, 256), (4, 128)]:
        for with_adam in (False, True):
            bench(depth, width, a.batch, a.iters, with_adam)


if __name__ == "__main__":
    main()
