"""What the body-part net costs the tracker per frame, beside the forest, one core.

Each frame the tracker asks for the part probabilities of its 400 points' pixels. The
net computes each pixel's whole row of depth-comparison features (500 offset pairs,
compiled, with a NumPy twin that gives the same float32 values) and three matrix
products; the forest descends its trees (20 levels, 3 trees) and also returns the leaves
that cast the joint votes. This prints the median milliseconds of each step on a frame
of the built-in motion, and of labelling the whole frame with each model.

Usage: OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_part_net.py
"""

from __future__ import annotations

import timeit

import numpy as np

from posedrift.benchmarks._track import simd_level
from posedrift.labelling import BodyPartForest, BodyPartNet
from posedrift.labelling._features import feature_matrix
from posedrift.labelling._net import _forward, _softmax
from posedrift.synthetic import build_sequence, procedural_motion


def median_ms(fn, number: int = 20, repeat: int = 7) -> float:
    return 1e3 * float(np.median(timeit.repeat(fn, number=number, repeat=repeat))) / number


def main(points: int = 400) -> None:
    frame = build_sequence(procedural_motion(), n_frames=40, rng=0).frames[39]
    depth, camera = frame.depth, frame.intrinsics
    mask = depth > 0
    person = np.argwhere(mask)
    pixels = person[np.linspace(0, len(person) - 1, points).astype(int)]
    net, forest = BodyPartNet.load_default(), BodyPartForest.load_default()
    options = {"reference_focal": net.reference_focal, "background": net.background}
    features = feature_matrix(depth, mask, pixels, net.offsets, camera, **options)
    clipped = np.clip(features, -net.clip, net.clip)
    print(
        f"{points} pixels of a {camera.width} x {camera.height} frame ({len(person)} person "
        f"pixels), {simd_level()}; net {net.n_features} features, hidden {list(net.hidden)}"
    )
    print("| what | ms |\n|---|---:|")
    for name, fn, number in [
        (
            "net: feature matrix, compiled",
            lambda: feature_matrix(depth, mask, pixels, net.offsets, camera, **options),
            20,
        ),
        (
            "net: feature matrix, NumPy twin",
            lambda: feature_matrix(
                depth, mask, pixels, net.offsets, camera, compiled=False, **options
            ),
            20,
        ),
        (
            "net: the three layers and softmax",
            lambda: _softmax(_forward(clipped, net.weights, net.biases)),
            20,
        ),
        (
            "net: predict_pixels (all of it)",
            lambda: net.predict_pixels(depth, pixels, camera, mask=mask),
            20,
        ),
        (
            "forest: predict_pixels with leaves (for the votes)",
            lambda: forest.predict_pixels(depth, pixels, camera, mask=mask, return_leaves=True),
            20,
        ),
        ("net: predict, the whole frame", lambda: net.predict(depth, mask, camera), 2),
        ("forest: predict, the whole frame", lambda: forest.predict(depth, mask, camera), 5),
    ]:
        print(f"| {name} | {median_ms(fn, number=number):.2f} |")


if __name__ == "__main__":
    main()
