"""``posedrift eval synthetic`` and ``posedrift eval utd``: Table 1, every method, one run."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from posedrift.cli._app import eval_app, fail, progress_enabled
from posedrift.cli._options import (
    CameraTiltOption,
    NetOption,
    SmoothLagOption,
    SmoothOption,
    TurnedNetOption,
    check_smoothing,
    load_part_net,
)

_METHODS_HELP = (
    "Comma-separated methods: cpd, shotton, pda, icp, shotton-net (Shotton's joints from "
    "the part net's labels), and the ablations cpd-frontal (the frontal part net for "
    "every view, no turned net), cpd-noback (the turned net for a person's back too, no "
    "back net), cpd-noside (the turned net for a person's side, no side net), "
    "cpd-forest (the forest's labels, no part net), cpd-paper, "
    "icp-paper (the paper's pure tracking, no per-frame evidence), "
    "cpd-norelabel, cpd-novotes (no joint votes), cpd-rigid, cpd-cold, cpd-reinit (a failed "
    "track always re-initialized), cpd-nofallback (CPD alone, no ICP second opinion), "
    "cpd-level (every camera taken for level: no tilt measured, no high net), "
    "cpd-nobrace (the hips where the thighs put them, no braced pelvis), "
    "cpd-nohold (joints outside the image from the prediction, no limbs held), "
    "cpd-noislands (stray upper-arm points fitted as labelled), "
    "cpd-200, cpd-400, cpd-800, cpd-fullres."
)


_REPEATS_HELP = (
    "Run the tracking methods (cpd, icp, the cpd ablations) N times with point-sampling "
    "seeds 0 .. N-1 and report their means, with the spread of the mean angle error "
    "(mean ± standard deviation); per-frame methods run once."
)


def _forest(model: Path | None):
    """The forest all methods share: loaded once here (None: the harness loads the default)."""
    if model is None:
        return None
    from posedrift.labelling import BodyPartForest

    try:
        return BodyPartForest.load(model)
    except ValueError as exc:
        raise fail(str(exc)) from exc


def _check_outputs(json_out: Path | None, figures: Path | None) -> None:
    """Fail now (exit 2), before any work, if --json or --figures cannot be written."""
    from posedrift.cli._outputs import check_output_dir, check_output_file

    if json_out is not None:
        check_output_file(json_out, "--json")
    if figures is not None:
        check_output_dir(figures, "--figures")


def _finish(report: dict, skipped: list[dict], json_out: Path | None, paper: bool) -> None:
    """Write the JSON, print the table; exit 1 if anything was skipped.

    Each skip was reported when it happened; only their count is repeated here.
    """
    import json

    from posedrift.evaluation import markdown_table

    report["skipped"] = skipped
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(report, indent=2) + "\n")
    typer.echo(markdown_table(report, paper=paper))
    if skipped:
        typer.echo(f"error: {len(skipped)} sequence(s) skipped (named above)", err=True)
        raise typer.Exit(1)


@eval_app.command("synthetic")
def eval_synthetic(
    sources: Annotated[
        list[str],
        typer.Argument(help="BVH motion files, or 'builtin' for the procedural clip."),
    ],
    frames: Annotated[
        int, typer.Option("--frames", min=2, help="Frames per clip (frame 0 is the T-pose).")
    ] = 500,
    methods: Annotated[str, typer.Option("--methods", help=_METHODS_HELP)] = "cpd,shotton,pda,icp",
    noise: Annotated[
        bool, typer.Option("--noise/--no-noise", help="Kinect-like depth noise.")
    ] = False,
    room: Annotated[
        bool,
        typer.Option(
            "--room/--no-room",
            help="Render the floor and a wall behind the person, which each method must "
            "segment away (with --noise: as a real camera sees a room).",
        ),
    ] = False,
    camera: Annotated[
        str | None,
        typer.Option(
            "--camera", help="Camera preset the clips are rendered for (default kinect1-qvga)."
        ),
    ] = None,
    distance: Annotated[
        float | None,
        typer.Option("--distance", help="Camera to person at frame 0, metres (default 2.8)."),
    ] = None,
    camera_height: Annotated[
        float | None,
        typer.Option(
            "--camera-height", help="Camera height above the floor, metres (default 1.0)."
        ),
    ] = None,
    camera_tilt: CameraTiltOption = 0.0,
    in_place: Annotated[
        bool,
        typer.Option(
            "--in-place/--world-motion",
            help="Remove the person's walking travel so they stay about 2.8 m away in view "
            "(the protocol's setting; angles unchanged), or keep the clip's own travel.",
        ),
    ] = True,
    there_and_back: Annotated[
        bool,
        typer.Option(
            "--there-and-back/--forward",
            help="Play the first half of the frames forward, then backward, so that the last "
            "frames repeat the first ones' poses (the drift test: per_sequence first_100_deg "
            "against last_100_deg).",
        ),
    ] = False,
    facing: Annotated[
        float,
        typer.Option(
            "--facing",
            help="Degrees the person is turned from the camera at frame 0, to their left "
            "(90 shows the right side, 180 the back; 0, facing the camera, is the protocol).",
        ),
    ] = 0.0,
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Write the results (JSON) here.")
    ] = None,
    figures: Annotated[
        Path | None,
        typer.Option("--figures", help="Write Fig. 9, 6, 12 and a Bland-Altman plot (PNG) here."),
    ] = None,
    seed: Annotated[
        int, typer.Option("--seed", help="Seed of the depth noise (clip i uses seed + i).")
    ] = 0,
    paper: Annotated[
        bool, typer.Option("--paper/--no-paper", help="Show the paper's rows for reference.")
    ] = True,
    model: Annotated[
        Path | None,
        typer.Option(
            "--model", help="Body-part forest file shared by all methods (default: shipped)."
        ),
    ] = None,
    net: NetOption = None,
    turned_net: TurnedNetOption = None,
    height: Annotated[
        float | None,
        typer.Option(
            "--height",
            help="Body stature in metres, in (0.5, 2.5) (default: each clip's own skeleton's).",
        ),
    ] = None,
    girth: Annotated[
        float, typer.Option("--girth", help="Body girth factor, > 0 (1 = the default body).")
    ] = 1.0,
    repeats: Annotated[int, typer.Option("--repeats", min=1, help=_REPEATS_HELP)] = 1,
    smooth: SmoothOption = 0.0,
    smooth_lag: SmoothLagOption = None,
) -> None:
    """Render clips and evaluate every method on the same frames (the paper's Table 1).

    Each clip is resampled to 30 fps, starts from a T-pose, and is rendered at
    320 x 240 with the person 2.8 m away (the default body, or the --height and
    --girth asked for; another camera with --camera and --distance); the methods
    see only the depth frames.
    Prints the table in Markdown, then each angle's bias and 95% limits of
    agreement; a clip that cannot be read or mapped is named, skipped, and makes
    the exit status 1. A source given twice (the same file) is
    evaluated once; files of the same name in different folders get distinct
    sequence names (x, x-2, ...), each said on standard error.

    Example: posedrift eval synthetic builtin ../shared/data/mocap/cmu/002_05.bvh
    --frames 500 --methods cpd,shotton,pda,icp --json table1.json --figures figs
    """
    from posedrift.cli._synth import _check_range, _load_source
    from posedrift.evaluation import evaluate, parse_methods
    from posedrift.synthetic import build_sequence

    try:
        names = parse_methods(methods)
    except ValueError as exc:
        raise fail(str(exc)) from exc
    _check_range("--height", height, 0.5, 2.5)
    _check_range("--girth", girth, 0.0, None)
    _check_range("--distance", distance, 0.3, None)
    _check_range("--facing", facing, -360.0, 360.0)
    _check_range("--camera-height", camera_height, 0.0, None)
    _check_range("--camera-tilt", camera_tilt, -90.0, 90.0)
    _check_outputs(json_out, figures)
    check_smoothing(smooth, smooth_lag)
    placement = {} if distance is None else {"distance": distance}
    if camera_height is not None:
        placement["camera_height"] = camera_height
    if camera_tilt != 0.0:
        placement["camera_tilt"] = camera_tilt
    if camera is not None:
        from posedrift.camera import CAMERA_PRESETS

        if camera not in CAMERA_PRESETS:
            raise fail(f"--camera must be one of {', '.join(CAMERA_PRESETS)}. Got {camera!r}.")
        placement["intrinsics"] = CAMERA_PRESETS[camera]
    shape = {"girth": girth} if girth != 1.0 else None
    sequences, skipped = [], []
    for i, (source, label) in enumerate(_name_sources(sources)):
        try:
            motion = _load_source(source)  # its errors start with the file's name
            if progress_enabled():
                typer.echo(f"rendering {label} ({frames} frames)", err=True)
            seq = build_sequence(
                motion,
                n_frames=frames,
                noise=noise,
                background=room,
                in_place=in_place,
                there_and_back=there_and_back,
                facing=facing,
                **placement,
                shape=shape,
                stature=height,
                rng=seed + i,
                name=label,
            )
        except (ValueError, OSError, KeyError) as exc:
            message = str(exc)
            if not message.startswith(source):
                message = f"{source}: {message}"
            typer.echo(f"error: skipped {message}", err=True)
            skipped.append({"sequence": source, "reason": message})
            continue
        sequences.append(seq)
    if not sequences:
        _finish_empty(skipped, json_out, "synthetic")

    def unusable(name: str, reason: str) -> None:
        typer.echo(f"error: skipped {name}: {reason}", err=True)
        skipped.append({"sequence": name, "reason": reason})

    try:
        report = evaluate(
            sequences,
            names,
            forest=_forest(model),
            part_net=load_part_net(net, turned_net),
            progress=progress_enabled(),
            figures_dir=figures,
            protocol="synthetic",
            on_skip=unusable,
            repeats=repeats,
            smooth=smooth,
            smooth_lag=smooth_lag,
        )
    except ValueError as exc:
        if str(exc).startswith("No sequence"):
            _finish_empty(skipped, json_out, "synthetic")
        raise fail(str(exc)) from exc
    report["noise"] = bool(noise)
    report["room"] = bool(room)
    report["camera"] = camera or "kinect1-qvga"
    report["distance"] = distance
    report["camera_height"] = camera_height
    report["camera_tilt"] = float(camera_tilt)
    report["in_place"] = bool(in_place)
    report["there_and_back"] = bool(there_and_back)
    report["facing"] = float(facing)
    report["body"] = {"height": height, "girth": girth}
    _finish(report, skipped, json_out, paper)


def _name_sources(sources: list[str]) -> list[tuple[str, str]]:
    """(source, sequence name) of each distinct source, in order.

    A source naming a file already given (``x.bvh``, ``./x.bvh``) is dropped;
    distinct files with the same stem are named ``x``, ``x-2``, ``x-3``... (a name
    no other source has as its stem). Each drop and rename is said on stderr.
    """

    def stem(source: str) -> str:
        return "builtin" if source == "builtin" else Path(source).stem

    def identity(source: str) -> str:
        return "builtin" if source == "builtin" else str(Path(source).resolve())

    stems = {stem(s) for s in sources}
    first: dict[str, str] = {}  # identity -> the source first naming it
    owner: dict[str, str] = {}  # sequence name -> source
    named: list[tuple[str, str]] = []
    for source in sources:
        key = identity(source)
        if key in first:
            typer.echo(
                f"warning: {source} is given more than once (as {first[key]}): evaluated once",
                err=True,
            )
            continue
        first[key] = source
        label = stem(source)
        if label in owner:
            base, k = label, 2
            while f"{base}-{k}" in owner or f"{base}-{k}" in stems:
                k += 1
            label = f"{base}-{k}"
            typer.echo(
                f"note: {source} is evaluated as {label!r} ({owner[base]} is {base!r})", err=True
            )
        owner[label] = source
        named.append((source, label))
    return named


def _finish_empty(skipped: list[dict], json_out: Path | None, protocol: str) -> None:
    import json

    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        report = {"protocol": protocol, "frames": 0, "sequences": [], "methods": {}}
        report["skipped"] = skipped
        json_out.write_text(json.dumps(report, indent=2) + "\n")
    raise fail("nothing to evaluate: every sequence was skipped (named above)", code=1)


@eval_app.command("utd")
def eval_utd(
    root: Annotated[Path, typer.Argument(help="UTD-MHAD folder holding Depth/ and Skeleton/.")],
    methods: Annotated[str, typer.Option("--methods", help=_METHODS_HELP)] = "cpd,shotton,pda,icp",
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Write the results (JSON) here.")
    ] = None,
    sequences: Annotated[
        str | None,
        typer.Option("--sequences", help="Comma-separated names, e.g. a1_s1_t1,a6_s2_t1."),
    ] = None,
    limit: Annotated[
        int | None, typer.Option("--limit", min=1, help="Only the first N sequences.")
    ] = None,
    figures: Annotated[
        Path | None,
        typer.Option("--figures", help="Write Fig. 9, 12 and a Bland-Altman plot (PNG) here."),
    ] = None,
    paper: Annotated[
        bool, typer.Option("--paper/--no-paper", help="Show the paper's rows for reference.")
    ] = False,
    model: Annotated[
        Path | None,
        typer.Option(
            "--model", help="Body-part forest file shared by all methods (default: shipped)."
        ),
    ] = None,
    net: NetOption = None,
    turned_net: TurnedNetOption = None,
    convention: Annotated[
        str,
        typer.Option(
            "--convention",
            help="Score joints moved to this skeleton convention: kinect (the reference's) "
            "or native (as recovered).",
        ),
    ] = "kinect",
    repeats: Annotated[int, typer.Option("--repeats", min=1, help=_REPEATS_HELP)] = 1,
    smooth: SmoothOption = 0.0,
    smooth_lag: SmoothLagOption = None,
) -> None:
    """Evaluate every method on UTD-MHAD against the Kinect SDK skeleton.

    The Kinect skeleton is itself an estimate: errors are against a reference, not
    ground truth. Kinect places joints differently (higher hips, lower shoulders...):
    by default every method's joints are moved to the Kinect convention by fixed
    offsets fitted once on development recordings (posedrift.skeleton.to_convention);
    the JSON keeps the unconverted errors under "native". Images are un-mirrored
    before the methods see them. A sequence whose files are missing, unreadable,
    empty, or whose skeleton is shorter than its depth or never tracked, is named,
    skipped, and makes the exit status 1.

    Sequences are the files a<action>_s<subject>_t<trial>_depth.mat (any case) with
    their _skeleton.mat. Other *_depth.mat / *_skeleton.mat files (e.g. "a5_s1_t1
    (copy)_depth.mat") are named in a warning and left out, without changing the
    exit status; --sequences "a5_s1_t1 (copy)" evaluates one. A name repeated in
    --sequences is evaluated once. --limit counts the sequences in order, usable
    or not.

    Example: posedrift eval utd ../shared/data/utd-mhad --limit 10 --json utd.json
    """
    from posedrift.evaluation import (
        evaluate,
        find_utd_sequences,
        load_utd_sequence,
        parse_methods,
    )
    from posedrift.skeleton import CONVENTIONS

    if convention not in CONVENTIONS:
        raise fail(
            f"Unknown --convention {convention!r}: expected one of {', '.join(CONVENTIONS)}."
        )
    try:
        names = parse_methods(methods)
    except ValueError as exc:
        raise fail(str(exc)) from exc
    _check_outputs(json_out, figures)
    check_smoothing(smooth, smooth_lag)
    wanted = None
    if sequences is not None:
        wanted = [s.strip() for s in sequences.split(",") if s.strip()]
        if not wanted:
            raise fail(
                f"--sequences {sequences!r} names no sequence: give comma-separated names, "
                "e.g. a1_s1_t1,a6_s2_t1."
            )

    def ignored(item: str, reason: str) -> None:
        typer.echo(f"warning: {item}: {reason}", err=True)

    try:
        found, missing = find_utd_sequences(root, names=wanted, limit=limit, on_ignored=ignored)
    except ValueError as exc:
        raise fail(str(exc)) from exc
    skipped = [{"sequence": n, "reason": r} for n, r in missing]
    for item in skipped:
        typer.echo(f"error: skipped {item['sequence']}: {item['reason']}", err=True)

    def unusable(name: str, reason: str) -> None:
        typer.echo(f"error: skipped {name}: {reason}", err=True)
        skipped.append({"sequence": name, "reason": reason})

    def loaded():
        for name, depth, skel in found:
            try:
                seq = load_utd_sequence(depth, skel, name=name)
            except ValueError as exc:
                typer.echo(f"error: skipped {name}: {exc}", err=True)
                skipped.append({"sequence": name, "reason": str(exc)})
                continue
            yield seq

    if not found:
        _finish_empty(skipped, json_out, "utd")
    try:
        report = evaluate(
            loaded(),
            names,
            forest=_forest(model),
            part_net=load_part_net(net, turned_net),
            progress=progress_enabled(),
            figures_dir=figures,
            protocol="utd",
            convention=convention,
            on_skip=unusable,
            repeats=repeats,
            smooth=smooth,
            smooth_lag=smooth_lag,
        )
    except ValueError as exc:
        if str(exc).startswith("No sequence"):
            _finish_empty(skipped, json_out, "utd")
        raise fail(str(exc)) from exc
    _finish(report, skipped, json_out, paper)
