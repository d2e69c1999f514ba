"""The evaluation report as a Markdown table in the layout of the paper's Table 1."""

from __future__ import annotations

from collections.abc import Mapping

from posedrift.evaluation._metrics import SEEN_TOLERANCE
from posedrift.skeleton import ANGLE_NAMES

PAPER_TABLE1: dict[str, tuple[float, ...]] = {
    "Shotton et al. [9]": (9.24, 9.41, 9.12, 9.81, 9.91, 10.15, 10.34, 9.67, 9.70),
    "Dinh et al. [15] (PDA)": (5.69, 5.63, 6.47, 6.88, 8.22, 8.73, 8.37, 6.84, 7.10),
    "its proposed method (CPD)": (5.54, 5.72, 5.32, 5.64, 8.02, 8.27, 6.40, 5.21, 6.26),
}
"""The paper's Table 1 (degrees; ``ANGLE_NAMES`` order, then the mean), on its own data."""

_HEADERS = {
    "left_elbow": "L elbow",
    "right_elbow": "R elbow",
    "left_shoulder": "L shoulder",
    "right_shoulder": "R shoulder",
    "left_knee": "L knee",
    "right_knee": "R knee",
    "left_hip": "L hip",
    "right_hip": "R hip",
}


def _fmt(value: float | None, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _in_view_note(report: Mapping) -> str:
    """A line on the angles whose reference joints leave the image, where there are any."""
    rows = {name: row["in_view"] for name, row in report["methods"].items() if "in_view" in row}
    shares = [v["angle_share"] for v in rows.values() if v.get("angle_share") is not None]
    if not shares or min(shares) >= 1.0:
        return ""
    means = ", ".join(
        f"{name} {_fmt(v['angle_error_mean_deg'])} ({_fmt(v['out_of_view_angle_error_mean_deg'])})"
        for name, v in rows.items()
    )
    return (
        f"\n{100 * (1 - min(shares)):.1f}% of the reference's angles have a joint outside the "
        f"image. Mean angle error over the angles in view (and over the rest): {means}.\n"
    )


def _seen_table(report: Mapping) -> str:
    """The angle errors over the angles whose joints the frames show, where some are hidden."""
    rows = {name: row["seen"] for name, row in report["methods"].items() if "seen" in row}
    shares = [v["angle_share"] for v in rows.values() if v.get("angle_share") is not None]
    if not shares or min(shares) >= 1.0:
        return ""
    headers = ["Method", *(_HEADERS[a] for a in ANGLE_NAMES), "Mean", "seen", "hidden"]
    lines = [
        f"\n{100 * (1 - min(shares)):.1f}% of the reference's angles have a joint the frames "
        f"do not show (outside the image, or more than {100 * SEEN_TOLERANCE:.0f} cm behind "
        "what the camera sees: posedrift.evaluation.angles_seen). Over the angles seen, "
        "degrees (the share seen; the mean over the hidden ones):\n",
        "| " + " | ".join(headers) + " |",
        "|" + "|".join(["---"] + ["---:"] * (len(headers) - 1)) + "|",
    ]
    for name, seen in rows.items():
        errors = seen["angle_error_deg"]
        cells = [name, *(_fmt(errors.get(a)) for a in ANGLE_NAMES), _fmt(errors.get("mean"))]
        share = seen.get("angle_share")
        cells.append("-" if share is None else f"{100 * share:.1f}%")
        cells.append(_fmt(seen.get("hidden_angle_error_mean_deg")))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _signed(value: float | None) -> str:
    return "-" if value is None else f"{value:+.1f}"


def _agreement_table(report: Mapping) -> str:
    """Each method's bias and 95% limits of agreement per angle, where the report has them."""
    rows = {
        name: row["angle_agreement"]
        for name, row in report["methods"].items()
        if "angle_agreement" in row
    }
    if not rows:
        return ""
    lines = [
        "\nAgreement with the reference (Bland-Altman), degrees: bias, estimate minus "
        "reference (95% limits of agreement).\n",
        "| Method | " + " | ".join(_HEADERS[a] for a in ANGLE_NAMES) + " |",
        "|" + "|".join(["---"] + ["---:"] * len(ANGLE_NAMES)) + "|",
    ]
    for name, agreement in rows.items():
        cells = [name]
        for angle in ANGLE_NAMES:
            a = agreement.get(angle, {})
            cell = _signed(a.get("bias_deg"))
            if a.get("loa_low_deg") is not None:
                cell += f" ({_signed(a['loa_low_deg'])}, {_signed(a['loa_high_deg'])})"
            cells.append(cell)
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def markdown_table(report: Mapping, *, paper: bool = True) -> str:
    """Table 1 of the paper for one evaluation (the JSON of ``posedrift eval``).

    Rows are the methods; columns the eight mean absolute angle errors (degrees,
    the paper's order), their mean, then MPJPE (mm), mAP@10cm, frames per second
    and failed frames. A method run several times (``evaluate(repeats=)``) shows
    its mean over the runs and their standard deviation (``mean ± sd``). Where some of
    the reference's angles have a joint outside the image, a line under the table
    gives each method's error over the angles in view and over the rest (``in_view``);
    where some have a joint the frames do not show, a table gives the errors over the
    angles seen (``seen``). A last table gives each angle's bias and 95% limits of agreement
    (``angle_agreement``), where the report has them.

    Parameters
    ----------
    report : mapping
        As returned by :func:`posedrift.evaluation.evaluate`.
    paper : bool
        Also list the paper's three rows below a separator, marked as measured on
        the paper's own data (they are not comparable frame for frame).

    Returns
    -------
    str
        Markdown, ending with a newline.

    Examples
    --------
    >>> row = {"angle_error_deg": dict.fromkeys(
    ...     ("left_elbow", "right_elbow", "left_shoulder", "right_shoulder", "left_knee",
    ...      "right_knee", "left_hip", "right_hip", "mean"), 1.0),
    ...     "mpjpe_mm": 50.0, "map_10cm": 0.9, "label_accuracy": None,
    ...     "frames_per_second": 10.0, "failed_frames": 0}
    >>> print(markdown_table({"protocol": "synthetic", "frames": 3, "sequences": ["a"],
    ...                       "methods": {"cpd": row}}, paper=False).splitlines()[2][:39])
    | cpd | 1.00 | 1.00 | 1.00 | 1.00 | 1.0
    """
    headers = (
        ["Method"]
        + [_HEADERS[a] for a in ANGLE_NAMES]
        + ["Mean", "MPJPE (mm)", "mAP@10cm", "fps", "failed"]
    )
    lines = [
        "| " + " | ".join(headers) + " |",
        "|" + "|".join(["---"] + ["---:"] * (len(headers) - 1)) + "|",
    ]
    for name, row in report["methods"].items():
        errors = row["angle_error_deg"]
        cells = [name] + [_fmt(errors.get(a)) for a in ANGLE_NAMES]
        mean = f"**{_fmt(errors.get('mean'))}**"
        if "repeats" in row:  # the spread over the runs with other point samples
            mean += f" ± {_fmt(row['repeats']['sd_deg'])}"
        cells.append(mean)
        cells.append(_fmt(row.get("mpjpe_mm"), 1))
        cells.append(_fmt(row.get("map_10cm"), 3))
        cells.append(_fmt(row.get("frames_per_second"), 1))
        cells.append(str(row.get("failed_frames", "-")))
        lines.append("| " + " | ".join(cells) + " |")
    if paper:
        for name, values in PAPER_TABLE1.items():
            cells = [f"*paper: {name}*"] + [f"{v:.2f}" for v in values[:-1]]
            cells += [f"*{values[-1]:.2f}*", "-", "-", "-", "-"]
            lines.append("| " + " | ".join(cells) + " |")
    text = "\n".join(lines) + "\n"
    convention = report.get("convention", "native")
    if convention != "native":
        native = ", ".join(
            f"{name} {_fmt(row['native'].get('mpjpe_mm'), 1)} mm / "
            f"{_fmt(row['native'].get('map_10cm'), 3)}"
            for name, row in report["methods"].items()
            if "native" in row
        )
        text += (
            f"\nJoints scored in the {convention} convention (fixed per-joint offsets, "
            f"posedrift.skeleton.to_convention). Unconverted MPJPE / mAP@10cm: {native}.\n"
        )
    if report.get("smoothing_s"):
        lag = report.get("smoothing_lag_s")
        window = "" if lag is None else f", using frames at most {lag:g} s after each"
        text += (
            f"\nEvery method's joints smoothed in time before scoring (--smooth "
            f"{report['smoothing_s']:g} s{window}; posedrift.tracking.smooth_results).\n"
        )
    text += _in_view_note(report) + _seen_table(report)
    if paper:
        text += (
            "\nRows marked *paper* are the paper's Table 1, measured on its own synthetic data "
            "(not available); they are not comparable frame for frame with the rows above.\n"
        )
    return text + _agreement_table(report)
