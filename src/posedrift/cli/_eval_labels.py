"""``posedrift eval labels``: per-pixel accuracy of the forest or the net on a synth folder."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from posedrift.cli._app import eval_app, fail, progress_enabled


@eval_app.command("labels")
def eval_labels(
    folder: Annotated[
        Path, typer.Argument(help="A folder written by 'posedrift synth' (depth/, labels/).")
    ],
    json_out: Annotated[Path, typer.Option("--json", help="Where to write the JSON result.")],
    model: Annotated[
        Path | None,
        typer.Option("--model", help="Model file of the --classifier (default: shipped model)."),
    ] = None,
    classifier: Annotated[
        str, typer.Option("--classifier", help="forest (the body-part forest) or net.")
    ] = "forest",
    png: Annotated[
        Path | None,
        typer.Option("--png", help="Picture of a few frames (default: beside the JSON)."),
    ] = None,
    frames: Annotated[
        int | None, typer.Option("--frames", min=1, help="Evaluate only the first N frames.")
    ] = None,
) -> None:
    """Label every frame of a synth folder with the forest (or net) and compare with the truth.

    Writes {"pixel_accuracy", "per_part", "frames", "ms_per_frame", "by_distance",
    "skipped"} to the JSON and a PNG of a few frames (depth | truth | prediction).
    A frame that cannot be read is named, skipped ("skipped": [{"frame", "reason"}]),
    and makes the exit status 1; the other frames are still evaluated.

    Example: posedrift synth builtin --out walk && posedrift eval labels walk --json acc.json
    """
    import json

    from posedrift.cli._outputs import check_output_file
    from posedrift.labelling import BodyPartForest, BodyPartNet
    from posedrift.labelling._train import evaluate_label_folder

    check_output_file(json_out, "--json")
    if png is None:
        png = json_out.with_suffix(".png")
    check_output_file(png, "--png")
    kinds = {"forest": BodyPartForest, "net": BodyPartNet}
    if classifier not in kinds:
        raise fail(f"--classifier must be 'forest' or 'net'. Got {classifier!r}.")
    kind = kinds[classifier]
    try:
        forest = kind.load(model) if model is not None else kind.load_default()
    except ValueError as exc:
        raise fail(str(exc)) from exc

    skipped: list[dict[str, str]] = []

    def on_skip(name: str, reason: str) -> None:  # reported once, as it happens
        skipped.append({"frame": name, "reason": reason})
        typer.echo(f"error: {folder}: skipped frame {name}: {reason}", err=True)

    try:
        result = evaluate_label_folder(
            folder,
            forest,
            max_frames=frames,
            png=png,
            progress=progress_enabled(),
            on_skip=on_skip,
        )
    except ValueError as exc:
        raise fail(str(exc)) from exc
    result["skipped"] = skipped
    json_out.parent.mkdir(parents=True, exist_ok=True)
    json_out.write_text(json.dumps(result, indent=2) + "\n")
    if not result["frames"]:
        raise fail(f"nothing to evaluate: every frame of {folder} was skipped", code=1)
    if result["pixel_accuracy"] is None:
        raise fail(f"nothing to score: no frame of {folder} shows the person", code=1)
    typer.echo(
        f"pixel accuracy {result['pixel_accuracy']:.3f} over {result['frames']} frames"
        + (f" ({len(skipped)} skipped)" if skipped else "")
        + f", {result['ms_per_frame']:.1f} ms per frame -> {json_out} ({png})"
    )
    if skipped:
        raise typer.Exit(1)
