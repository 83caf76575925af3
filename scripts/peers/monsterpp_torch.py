#!/usr/bin/env python3
"""The PyTorch side of `seasonstereo bench monsterpp`: the upstream MonSter++ network
(random weights, CPU, fp32, inference) timed the same way, with per-module times.

Usage (torch from PyPI in a scratch venv outside the repository; the upstream code fetched
with `fetch github:Junda24/MonSter-plusplus` and checked out somewhere):

    python scripts/peers/monsterpp_torch.py --upstream /path/to/MonSter-plusplus \
        --config vits --height 256 --width 512 --iters 12 --max-disp 192 --runs 3 \
        --threads 2 [--profile] [--json]

Prints the median and minimum seconds of the timed runs (after one warm-up) and the process's
peak RSS; `--profile` adds one more pass with every module group timed (wall clock, the same
groups as `seasonstereo bench monsterpp --profile`) and torch.profiler's view of the same
labels.
"""

import argparse
import json
import os
import resource
import statistics
import sys
import time
from argparse import Namespace
from collections import defaultdict


def parse():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--upstream", required=True, help="checkout of Junda24/MonSter-plusplus")
    p.add_argument("--config", default="vits", choices=["vits", "vitb", "vitl"])
    p.add_argument("--height", type=int, default=256)
    p.add_argument("--width", type=int, default=512)
    p.add_argument("--iters", type=int, default=12)
    p.add_argument("--max-disp", type=int, default=192)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--profile", action="store_true")
    p.add_argument("--json", action="store_true")
    return p.parse_args()


# Module groups, in pass order; the names match the Rust profile's.
GROUPS = {
    "dinov2": ["mono_encoder.get_intermediate_layers"],
    "dpt heads": ["mono_decoder", "feat_decoder"],
    "feature stems + context": ["feat_transfer", "stem_2", "stem_4", "stem_8", "stem_16",
                                "conv", "desc", "feat_transfer_cnet", "context_zqr_convs"],
    "gwc volume": ["build_gwc_volume"],
    "3-d hourglass + init disparity": ["corr_stem", "corr_feature_att", "cost_agg", "classifier"],
    "geo encoding lookup": ["Combined_Geo_Encoding_Volume"],
    "convgru updates": ["update_block", "update_block_mix_stereo", "update_block_mix_mono"],
    "mutual refinement (warp, scale/shift)": ["disp_warp", "compute_scale_shift"],
    "upsampling": ["upsample_disp"],
    "remp": ["REMP"],
}


class Timers:
    def __init__(self):
        self.seconds = defaultdict(float)
        self.enabled = False

    def wrap(self, label, fn):
        import torch

        def timed(*args, **kwargs):
            if not self.enabled:
                return fn(*args, **kwargs)
            t = time.perf_counter()
            with torch.profiler.record_function(label):
                out = fn(*args, **kwargs)
            self.seconds[label] += time.perf_counter() - t
            return out

        return timed


def build(args, timers):
    import torch
    import torch.nn.functional as F

    root = os.path.join(os.path.abspath(args.upstream), "MonSter++")
    sys.path.insert(0, root)
    sys.path.insert(0, os.path.join(root, "Depth-Anything-V2-list3"))
    from depth_anything_v2.dpt import DepthAnythingV2

    model_configs = {
        "vits": {"encoder": "vits", "features": 64, "out_channels": [48, 96, 192, 384]},
        "vitb": {"encoder": "vitb", "features": 128, "out_channels": [96, 192, 384, 768]},
        "vitl": {"encoder": "vitl", "features": 256, "out_channels": [256, 512, 1024, 1024]},
    }
    # Random weights: the constructor's Depth Anything checkpoint is a fresh model's state.
    real_load = torch.load
    torch.load = lambda *a, **k: DepthAnythingV2(**model_configs[args.config]).state_dict()
    import core.monster as monster

    margs = Namespace(encoder=args.config, hidden_dims=[128] * 3, n_gru_layers=3, corr_levels=2,
                      corr_radius=4, n_downsample=2, max_disp=args.max_disp,
                      corr_implementation="reg", mixed_precision=False, shared_backbone=False,
                      slow_fast_gru=False)
    model = monster.Monster(margs).eval()
    torch.load = real_load

    for label in ["build_gwc_volume", "disp_warp", "compute_scale_shift"]:
        setattr(monster, label, timers.wrap(label, getattr(monster, label)))
    monster.Combined_Geo_Encoding_Volume = timed_class(timers, monster.Combined_Geo_Encoding_Volume)
    enc = model.mono_encoder
    enc.get_intermediate_layers = timers.wrap("mono_encoder.get_intermediate_layers", enc.get_intermediate_layers)
    model.upsample_disp = timers.wrap("upsample_disp", model.upsample_disp)
    for names in GROUPS.values():
        for name in names:
            module = getattr(model, name, None)
            if isinstance(module, torch.nn.ModuleList):
                for m in module:
                    m.forward = timers.wrap(name, m.forward)
            elif isinstance(module, torch.nn.Module):
                module.forward = timers.wrap(name, module.forward)
    return model, F


def timed_class(timers, cls):
    """The geometry volume: its construction (pyramids) and every lookup call, one label."""
    label = "Combined_Geo_Encoding_Volume"

    class Timed(cls):
        def __init__(self, *a, **k):
            timers.wrap(label, super().__init__)(*a, **k)

        def __call__(self, *a, **k):
            return timers.wrap(label, super().__call__)(*a, **k)

    return Timed


def main():
    args = parse()
    import torch

    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    timers = Timers()
    model, _ = build(args, timers)
    shape = (1, 3, args.height, args.width)
    left = torch.rand(shape) * 255
    right = torch.rand(shape) * 255

    def run():
        with torch.inference_mode():
            return model(left, right, iters=args.iters, test_mode=True)

    run()
    times = []
    for _ in range(args.runs):
        t = time.perf_counter()
        run()
        times.append(time.perf_counter() - t)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    result = {"median_s": statistics.median(times), "min_s": min(times), "times_s": times,
              "peak_rss_mib": peak, "torch": torch.__version__, "threads": args.threads,
              "config": args.config, "height": args.height, "width": args.width,
              "iters": args.iters, "max_disp": args.max_disp}
    if args.profile:
        timers.enabled = True
        t = time.perf_counter()
        with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU]) as prof:
            run()
        total = time.perf_counter() - t
        timers.enabled = False
        by_label = {e.key: e.cpu_time_total / 1e6 for e in prof.key_averages()}
        groups = {}
        for group, labels in GROUPS.items():
            groups[group] = {"wall_s": sum(timers.seconds[n] for n in labels),
                             "profiler_s": sum(by_label.get(n, 0.0) for n in labels)}
        result["profile"] = {"total_s": total, "groups": groups}
    if args.json:
        print(json.dumps(result))
        return
    print(f"MonSter++ {args.config} {args.height}x{args.width}, {args.iters} iterations, "
          f"max_disp {args.max_disp}, torch {torch.__version__}, {args.threads} threads")
    print(f"median {result['median_s']:.3f} s, min {result['min_s']:.3f} s over {args.runs} runs; "
          f"peak RSS {peak:.0f} MiB")
    if args.profile:
        print(f"profiled pass {result['profile']['total_s']:.3f} s (under the profiler)")
        for group, t in result["profile"]["groups"].items():
            print(f"  {group:40s} {t['wall_s']:8.3f} s  (torch.profiler {t['profiler_s']:.3f} s)")


if __name__ == "__main__":
    main()
