#!/usr/bin/env python3
"""The PyTorch side of `seasonstereo bench train-step`: one training step of the upstream MonSter++
(random weights, CPU, fp32): train-mode forward with BatchNorm2d frozen (`model.train();
model.freeze_bn()`, mono encoder and decoder frozen as upstream builds them), upstream's
`sequence_loss` (train_*.py) on a random disparity, backward, gradient clipping at 1.0 and an
AdamW step. The Rust step's loss is SeasonStereo's (disparity + photometric + smoothness), which
adds a warp and a few element-wise passes per prediction to the same forward and backward.

Usage (see monsterpp_torch.py for the venv and the upstream checkout):

    python scripts/peers/train_step_torch.py --upstream /path/to/MonSter-plusplus --config vits \
        --height 128 --width 128 --batch 1 --iters 7 --max-disp 192 --runs 3 --threads 2 [--json]
"""

import argparse
import json
import os
import resource
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import monsterpp_torch  # noqa: E402  (the model builder)


def parse():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--upstream", required=True)
    p.add_argument("--config", default="vits", choices=["vits", "vitb", "vitl"])
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--batch", type=int, default=1)
    p.add_argument("--iters", type=int, default=7)
    p.add_argument("--max-disp", type=int, default=192)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--json", action="store_true")
    return p.parse_args()


def sequence_loss(F, disp_preds, disp_init_pred, disp_gt, valid, loss_gamma=0.9, max_disp=192):
    """Upstream's training loss (train_sceneflow.py), without its metrics."""
    n = len(disp_preds)
    mag = (disp_gt ** 2).sum(dim=1).sqrt()
    valid = ((valid >= 0.5) & (mag < max_disp)).unsqueeze(1)
    init_valid = valid & ~disp_init_pred.isnan()
    loss = F.smooth_l1_loss(disp_init_pred[init_valid], disp_gt[init_valid], reduction="mean")
    for i in range(n):
        gamma = loss_gamma ** (15 / (n - 1))
        i_loss = (disp_preds[i] - disp_gt).abs()
        loss = loss + gamma ** (n - i - 1) * i_loss[valid & ~i_loss.isnan()].mean()
    return loss


def main():
    args = parse()
    import torch

    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    model, F = monsterpp_torch.build(args, monsterpp_torch.Timers())
    model.train()
    model.freeze_bn()
    params = [p for p in model.parameters() if p.requires_grad]
    optimizer = torch.optim.AdamW(params, lr=2e-4, weight_decay=1e-5, eps=1e-8)
    b, h, w = args.batch, args.height, args.width
    left = torch.rand(b, 3, h, w) * 255
    right = torch.rand(b, 3, h, w) * 255
    gt = torch.rand(b, 1, h, w) * 32
    valid = torch.ones(b, h, w)

    def once():
        t = time.perf_counter()
        init_disp, disp_preds, _ = model(left, right, iters=args.iters, test_mode=False)
        loss = sequence_loss(F, disp_preds, init_disp, gt, valid, max_disp=args.max_disp)
        optimizer.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(params, 1.0)
        optimizer.step()
        return time.perf_counter() - t

    warmup = once()
    times = [once() for _ in range(args.runs)]
    rss_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    result = {"median_s": statistics.median(times), "min_s": min(times), "peak_rss_mib": rss_mib,
              "warmup_s": warmup, "times_s": times, "config": args.config,
              "shape": f"{h}x{w}", "batch": b, "iters": args.iters, "threads": args.threads,
              "torch": torch.__version__}
    if args.json:
        print(json.dumps(result))
    else:
        print(f"MonSter++ {args.config} training step {h}x{w}, batch {b}, {args.iters} iterations, "
              f"torch {torch.__version__}, {args.threads} threads")
        print(f"median {result['median_s']:.3f} s, min {result['min_s']:.3f} s over {args.runs} runs; "
              f"peak RSS {rss_mib:.0f} MiB")


if __name__ == "__main__":
    main()
