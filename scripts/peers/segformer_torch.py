#!/usr/bin/env python3
"""The PyTorch side of `seasonstereo bench segformer`: HF transformers'
`SegformerForSemanticSegmentation` in the release's layout (mit-b2, 9 OpenEarthMap labels), random
weights, CPU, fp32, eval + inference mode, one image of SIZE x SIZE, timed the same way (one
warm-up, then N runs; median, minimum, peak RSS).

Usage (torch and transformers from PyPI in a scratch venv outside the repository):

    python scripts/peers/segformer_torch.py --size 1000 --runs 3 --threads 2 [--json]
"""

import argparse
import json
import resource
import statistics
import time


def parse():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", type=int, default=1000)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--json", action="store_true")
    return p.parse_args()


def main():
    args = parse()
    import torch
    from transformers import SegformerConfig, SegformerForSemanticSegmentation

    torch.set_num_threads(args.threads)
    # nvidia/mit-b2, as `SegformerConfig::mit_b2(9)` on the Rust side.
    config = SegformerConfig(
        hidden_sizes=[64, 128, 320, 512], depths=[3, 4, 6, 3], num_attention_heads=[1, 2, 5, 8],
        sr_ratios=[8, 4, 2, 1], patch_sizes=[7, 3, 3, 3], strides=[4, 2, 2, 2],
        mlp_ratios=[4, 4, 4, 4], decoder_hidden_size=768, num_labels=9, num_channels=3,
    )
    model = SegformerForSemanticSegmentation(config).eval()
    x = torch.randn(1, 3, args.size, args.size)

    def once():
        with torch.inference_mode():
            t = time.perf_counter()
            model(pixel_values=x).logits.sum().item()
            return time.perf_counter() - t

    warmup = once()
    times = [once() for _ in range(args.runs)]
    rss_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    result = {"median_s": statistics.median(times), "min_s": min(times), "peak_rss_mib": rss_mib,
              "warmup_s": warmup, "times_s": times, "size": args.size, "threads": args.threads,
              "torch": torch.__version__}
    if args.json:
        print(json.dumps(result))
    else:
        print(f"SegFormer mit-b2 {args.size}x{args.size}, torch {torch.__version__}, {args.threads} threads")
        print(f"median {result['median_s']:.3f} s, min {result['min_s']:.3f} s over {args.runs} runs; "
              f"peak RSS {rss_mib:.0f} MiB")


if __name__ == "__main__":
    main()
