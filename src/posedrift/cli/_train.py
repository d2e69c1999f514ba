"""``posedrift train``: fit the body-part forest (or net) on freshly rendered synthetic frames."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer

from posedrift.cli._app import app, fail, progress_enabled


def _default_mocap() -> Path | None:
    root = Path(os.environ.get("POSEDRIFT_DATA", Path.cwd().parent / "shared" / "data"))
    return root / "mocap" if (root / "mocap").is_dir() else None


@app.command("train")
def train(
    out: Annotated[Path, typer.Option("--out", help="Where to write the model (.npz).")],
    classifier: Annotated[
        str,
        typer.Option(
            "--classifier",
            help="forest: the body-part forest (labels and joint votes; Shotton et al.); "
            "net: the body-part net (a perceptron over the same kind of depth features).",
        ),
    ] = "forest",
    frames: Annotated[
        int, typer.Option("--frames", min=1, help="Rendered training frames.")
    ] = 2000,
    seed: Annotated[int, typer.Option("--seed", help="Seed: the same seed, the same model.")] = 0,
    mocap: Annotated[
        Path | None,
        typer.Option(
            "--mocap",
            help="Folder of BVH clips (.bvh in any letter case), or one BVH file, for poses "
            "(default: $POSEDRIFT_DATA/mocap or ../shared/data/mocap when present; else the "
            "procedural motion only).",
        ),
    ] = None,
    exclude: Annotated[
        list[str] | None,
        typer.Option("--exclude", help="Glob of BVH file names to hold out (repeatable)."),
    ] = None,
    pixels: Annotated[
        int, typer.Option("--pixels", min=1, help="Pixels sampled per frame.")
    ] = 1000,
    offsets: Annotated[int, typer.Option("--offsets", min=1, help="Candidate offset pairs.")] = 500,
    trees: Annotated[int, typer.Option("--trees", min=1, help="Number of trees.")] = 3,
    depth: Annotated[int, typer.Option("--depth", min=1, max=64, help="Tree depth.")] = 20,
    min_leaf: Annotated[int, typer.Option("--min-leaf", min=1, help="Samples per leaf.")] = 5,
    max_features: Annotated[
        float, typer.Option("--max-features", help="Share of offsets tried per split.")
    ] = 0.1,
    extra_trees: Annotated[
        bool, typer.Option("--extra-trees/--random-forest", help="Random thresholds (faster).")
    ] = False,
    jobs: Annotated[int, typer.Option("--jobs", min=1, help="Threads for fitting.")] = 2,
    procedural_share: Annotated[
        float,
        typer.Option("--procedural-share", min=0.0, max=1.0, help="Share of procedural poses."),
    ] = 0.2,
    wide_share: Annotated[
        float,
        typer.Option(
            "--wide-share",
            min=0.0,
            max=1.0,
            help="Share of frames from wide views (nearer or farther, off-axis, turned).",
        ),
    ] = 0.3,
    wide_yaw: Annotated[
        float,
        typer.Option(
            "--wide-yaw", min=0.0, max=180.0, help="Largest turn of the wide views, degrees."
        ),
    ] = 100.0,
    wide_min_yaw: Annotated[
        float,
        typer.Option(
            "--wide-min-yaw",
            min=0.0,
            max=180.0,
            help="Smallest turn of the wide views, degrees (120 with --wide-share 1 "
            "--wide-yaw 180: people seen from behind only).",
        ),
    ] = 0.0,
    wide_left_side: Annotated[
        bool,
        typer.Option(
            "--wide-left-side",
            help="Turn every wide view one way, the person's left side towards the "
            "camera (the side net; the tracker mirrors it for the right side).",
        ),
    ] = False,
    camera_heights: Annotated[
        str,
        typer.Option(
            "--camera-heights",
            help="Range of the camera's height above the floor, metres, LOW,HIGH; half "
            "the frames look level, half down or up at the person's pelvis.",
        ),
    ] = "0.7,1.3",
    mirror_share: Annotated[
        float,
        typer.Option(
            "--mirror-share",
            min=0.0,
            max=1.0,
            help="Share of frames whose pose is mirrored left for right.",
        ),
    ] = 0.0,
    min_pose_distance: Annotated[
        float,
        typer.Option(
            "--min-pose-distance",
            min=0.0,
            help="Drop clip frames whose pose is within this many metres of a kept one "
            "(every joint), so that each distinct pose is equally likely; 0 keeps all "
            "frames and weights the clips equally.",
        ),
    ] = 0.05,
    vote_frames: Annotated[
        int,
        typer.Option(
            "--vote-frames",
            min=0,
            help="Fresh frames (after the trees) from which each leaf learns where the "
            "joints are (joint votes, used by the tracker); 0 for none.",
        ),
    ] = 20000,
    vote_radius: Annotated[
        float,
        typer.Option(
            "--vote-radius",
            min=0.01,
            help="A pixel votes only for joints within this many metres of it.",
        ),
    ] = 0.2,
    hidden: Annotated[
        str,
        typer.Option("--hidden", help="Net only: widths of the hidden layers, comma-separated."),
    ] = "256,256,128",
    epochs: Annotated[
        int, typer.Option("--epochs", min=1, help="Net only: passes over the sampled pixels.")
    ] = 8,
) -> None:
    """Train a body-part forest (needs scikit-learn) or net on rendered depth frames.

    Poses come from the BVH clips (all but the held-out ones; near-duplicate poses
    dropped, --min-pose-distance) and the procedural motion, bodies of varied height,
    girth and build, views within 45 degrees of frontal at 2-3.5 m and (--wide-share
    of the frames) wider views turned --wide-min-yaw to --wide-yaw degrees from
    frontal (either way, or with --wide-left-side the left side towards the camera) at
    1-4.5 m, Kinect-like noise on half of the frames. For a forest, then, on
    --vote-frames fresh frames drawn the same way, each leaf learns its pixels' offsets
    to the joints near them (joint votes). A net (--classifier net) keeps its sampled
    pixels' features in memory as float16: frames x pixels x offsets x 2 bytes.

    Example: posedrift train --frames 2000 --seed 0 --out forest.npz

    Example: posedrift train --classifier net --frames 12000 --pixels 600 --out net.npz
    """
    import time
    from dataclasses import replace

    import numpy as np

    from posedrift.cli._outputs import check_output_file
    from posedrift.labelling import _train as tr
    from posedrift.labelling import fit_joint_votes

    check_output_file(out, "--out")
    if classifier not in ("forest", "net"):
        raise fail(f"--classifier must be 'forest' or 'net'. Got {classifier!r}.")
    try:
        widths = tuple(int(w) for w in hidden.split(","))
        if not widths or min(widths) < 1:
            raise ValueError
    except ValueError:
        raise fail(f"--hidden must be positive widths, comma-separated. Got {hidden!r}.") from None
    try:
        heights = tuple(float(h) for h in camera_heights.split(","))
        if len(heights) != 2 or not 0.0 < heights[0] <= heights[1] < 5.0:
            raise ValueError
    except ValueError:
        raise fail(
            f"--camera-heights must be LOW,HIGH metres with 0 < LOW <= HIGH < 5. "
            f"Got {camera_heights!r}."
        ) from None
    if wide_min_yaw > wide_yaw:
        raise fail(f"--wide-min-yaw ({wide_min_yaw:g}) must not exceed --wide-yaw ({wide_yaw:g}).")
    if classifier == "forest":
        try:
            import sklearn  # noqa: F401
        except ImportError as exc:
            raise fail(
                "posedrift train needs scikit-learn: pip install 'posedrift[train]'"
            ) from exc
    exclude = list(exclude) if exclude else list(tr.HELD_OUT_CLIPS)
    mocap = mocap if mocap is not None else _default_mocap()
    started = time.perf_counter()
    try:
        paths = tr.training_clips(mocap, exclude=exclude)
        if mocap is not None and not paths:
            typer.echo(
                f"warning: no BVH clip to train on in {mocap} (after --exclude); "
                f"training on the procedural motion only.",
                err=True,
            )
        with tr._progress(progress_enabled(), "loading motions", len(paths) + 1) as advance:
            motions = tr.load_training_motions(paths, on_motion=lambda _: advance())
        # The votes draw from a third child stream, so the trees' two streams (and the
        # trees) are what they were before there were votes.
        render_rng, fit_rng, vote_rng = (
            np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3)
        )
        n_clips = len(motions) - 1
        share = procedural_share if n_clips else 1.0
        pose_frames = None
        if min_pose_distance > 0 and n_clips:
            # Each distinct clip pose equally likely, the procedural motion its share.
            pose_frames = tr.diverse_frames(motions[:-1], min_pose_distance, rng=seed)
            counts = np.array([len(f) for f in pose_frames], dtype=float)
            weights = list((1.0 - share) * counts / counts.sum()) + [share]
            pose_frames.append(np.arange(len(motions[-1].joints)))
        else:
            weights = [(1.0 - share) / max(n_clips, 1)] * n_clips + [share]
        ranges = tr.SceneRanges(
            camera_height=heights,
            wide_fraction=wide_share,
            wide_yaw=wide_yaw,
            wide_min_yaw=wide_min_yaw,
            wide_left_side=wide_left_side,
            mirror_fraction=mirror_share,
        )
        generator = tr.synthetic_training_frames(
            frames, motions, ranges=ranges, weights=weights, frames=pose_frames, rng=render_rng
        )
        metadata = {
            "command": "posedrift train" + (" --classifier net" if classifier == "net" else ""),
            "seed": seed,
            "frames": frames,
            "clips": [p.name for p in paths],
            "excluded": exclude,
            "procedural_share": share,
            "wide_share": wide_share,
            "wide_yaw": wide_yaw,
            "wide_min_yaw": wide_min_yaw,
            "wide_left_side": wide_left_side,
            "mirror_share": mirror_share,
            "camera_heights": list(heights),
            "min_pose_distance": min_pose_distance,
        }
        if classifier == "net":
            model = _train_net(tr, generator, frames, pixels, offsets, widths, epochs, fit_rng)
            path = replace(model, metadata={**model.metadata, **metadata}).save(out)
            typer.echo(
                f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB, a net of "
                f"{model.n_features} features and hidden layers {list(model.hidden)}) "
                f"in {time.perf_counter() - started:.0f} s"
            )
            return
        metadata.update(vote_frames=vote_frames, vote_radius=vote_radius)
        with tr._progress(progress_enabled(), "rendering + features", frames) as advance:
            forest = tr.train_forest(
                generator,
                n_frames=frames,
                n_offsets=offsets,
                pixels_per_frame=pixels,
                n_trees=trees,
                max_depth=depth,
                min_samples_leaf=min_leaf,
                max_features=max_features,
                extra_trees=extra_trees,
                n_jobs=jobs,
                rng=fit_rng,
                on_frame=lambda _: advance(),
                on_stage=lambda stage: typer.echo(f"fitting {trees} trees ...", err=True),
                metadata=metadata,
            )
        if vote_frames:
            vote_started = time.perf_counter()
            vote_source = tr.synthetic_training_frames(
                vote_frames,
                motions,
                ranges=ranges,
                weights=weights,
                frames=pose_frames,
                rng=vote_rng,
            )
            with tr._progress(progress_enabled(), "joint votes", vote_frames) as advance:
                votes = fit_joint_votes(
                    forest,
                    vote_source,
                    n_frames=vote_frames,
                    radius=vote_radius,
                    rng=vote_rng,
                    on_frame=lambda _: advance(),
                )
            metadata = {
                **forest.metadata,
                "vote_seconds": round(time.perf_counter() - vote_started, 1),
            }
            forest = replace(forest.with_votes(votes), metadata=metadata)
    except ValueError as exc:
        raise fail(str(exc)) from exc
    path = forest.save(out)
    size = path.stat().st_size / 1e6
    typer.echo(
        f"wrote {path} ({size:.1f} MB, {forest.n_trees} trees, {forest.n_nodes} nodes) "
        f"in {time.perf_counter() - started:.0f} s"
    )


def _train_net(tr, generator, frames, pixels, offsets, hidden, epochs, rng):
    """The body-part net of ``posedrift train --classifier net``, with progress."""
    with tr._progress(progress_enabled(), "rendering + features", frames) as advance:
        return tr.train_net(
            generator,
            n_frames=frames,
            n_offsets=offsets,
            pixels_per_frame=pixels,
            hidden=hidden,
            epochs=epochs,
            rng=rng,
            on_frame=lambda _: advance(),
            on_epoch=lambda e, loss: typer.echo(
                f"epoch {e + 1}/{epochs}: loss {loss:.4f}", err=True
            ),
        )
