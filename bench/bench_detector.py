"""Benchmark the baseline detector's training and inference speed on a device (CPU vs GPU).

Trains the given config for ``--steps`` steps on a COCO export (the real data path: cached images,
augmentation, targets, forward, backward, AdamW) after ``--warmup`` untimed steps, then times
inference over the same images. Prints one table: device, threads, steps/s, images/s (training),
images/s (inference, batch ``infer.batch_size``), and the projected time of the config's full run.
Run it once per device and compare the steps/s column for the speed-up.

    .venv/bin/python bench/bench_detector.py --coco DIR [--split train] [--config default]
        [--device cpu|cuda|auto] [--steps 50] [--warmup 5] [--threads N]
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path


def main() -> None:
    import torch

    from pipeline.detect.data import annotation_file, load_coco, read_rgb
    from pipeline.detect.infer import Detector, resolve_device
    from pipeline.detect.train import TrainImages, seed_everything
    from pipeline.stages.train import resolve_config

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--coco", type=Path, required=True)
    parser.add_argument("--split", default="train")
    parser.add_argument("--config", default="default")
    parser.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"))
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--warmup", type=int, default=5)
    parser.add_argument("--threads", type=int, help="CPU threads (default: the config's train.threads)")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)

    config, _ = resolve_config(args.config, conditions="all")
    device = resolve_device(args.device)
    data = load_coco(annotation_file(args.coco, args.split), config.classes)
    seed_everything(0, args.threads or config.train.threads, device)
    torch.use_deterministic_algorithms(False)  # speed, not bits, is measured here
    from pipeline.detect.losses import detection_loss
    from pipeline.detect.model import CenterNet

    model = CenterNet(len(config.classes), config.backbone).to(device).train()
    optimizer = torch.optim.AdamW(model.parameters(), lr=config.train.lr)
    samples = TrainImages(data, config, 0)
    bs = config.train.batch_size

    def step(i: int) -> None:
        images, targets = samples.batch(i, bs)
        losses = detection_loss(model(images.to(device)), {k: v.to(device) for k, v in targets.items()})
        optimizer.zero_grad(set_to_none=True)
        losses["loss"].backward()
        optimizer.step()

    for i in range(args.warmup):
        step(i)
    if device.type == "cuda":
        torch.cuda.synchronize()
    start = time.perf_counter()
    for i in range(args.warmup, args.warmup + args.steps):
        step(i)
    if device.type == "cuda":
        torch.cuda.synchronize()
    train_s = time.perf_counter() - start

    detector = Detector(model.eval(), config, data.category_ids, device)
    rgbs = [read_rgb(im.path) for im in data.images[: 8 * config.infer.batch_size]]
    detector.predict(rgbs[: config.infer.batch_size])
    start = time.perf_counter()
    for k in range(0, len(rgbs), config.infer.batch_size):
        detector.predict(rgbs[k:k + config.infer.batch_size])
    infer_s = time.perf_counter() - start

    name = torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu"
    sps = args.steps / train_s
    print(f"| device | threads | train steps/s | train img/s | infer img/s | full run ({config.train.steps} steps) |")
    print("| --- | --- | --- | --- | --- | --- |")
    print(f"| {name} | {torch.get_num_threads()} | {sps:.2f} | {sps * bs:.1f} | {len(rgbs) / infer_s:.1f} | "
          f"{config.train.steps / sps:.0f} s |")


if __name__ == "__main__":
    main()
