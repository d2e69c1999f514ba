"""Figures of an evaluation: the paper's Fig. 9 (angles over frames), Fig. 6 (label
maps) and Fig. 12 (skeletons on hard frames), and a Bland-Altman plot of every angle,
as PNG files."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from posedrift.camera import Intrinsics, project
from posedrift.evaluation._metrics import angle_agreement
from posedrift.skeleton import (
    ANGLE_NAMES,
    JOINT_INDEX,
    JOINT_PARENTS,
    PART_COLOURS,
    joint_angles,
    to_convention,
)

_COLOURS = ("tab:red", "tab:blue", "tab:purple", "tab:orange", "tab:brown", "tab:pink", "tab:cyan")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)


def angle_figure(run, sequence: str, path: Path) -> Path:
    """Fig. 9: each of the eight angles over frames, ground truth dashed, methods solid."""
    plt = _pyplot()
    record = next(r for r in run.sequences if r.name == sequence)
    ref = record.reference.angles
    frames = np.arange(len(ref))
    kind = "ground truth" if record.reference.kind == "synthetic" else "Kinect reference"
    fig, axes = plt.subplots(4, 2, figsize=(13, 11), sharex=True)
    for k, (ax, name) in enumerate(zip(axes.T.ravel(), ANGLE_NAMES, strict=True)):
        ax.plot(frames, ref[:, k], "k--", lw=1.6, label=kind)
        for i, method in enumerate(run.methods):
            est = run.runs[(method, sequence)].angles[:, k]
            ax.plot(frames, est, color=_COLOURS[i % len(_COLOURS)], lw=0.9, label=method)
        ax.set_title(name.replace("_", " "))
        ax.set_ylabel("degrees")
        ax.set_ylim(-5, 185)
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("frame")
    axes[0, 0].legend(loc="lower left", fontsize=8, ncol=2)
    fig.suptitle(f"Estimated (solid) and {kind} (dashed) joint angles: {sequence}")
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def agreement_figure(run, path: Path, *, convention: str = "native") -> Path:
    """Bland-Altman plot of each angle over every sequence: difference against mean.

    One panel per angle, one colour per method: each frame's ``est - ref`` against
    ``(est + ref) / 2``, with the method's bias (solid) and 95% limits of agreement
    (dotted) as :func:`~posedrift.evaluation.angle_agreement` gives them; the angles
    are the scored ones (joints moved to ``convention`` first, as the report does).
    """
    plt = _pyplot()
    ref = np.concatenate([r.reference.angles for r in run.sequences])
    kind = "ground truth" if run.sequences[0].reference.kind == "synthetic" else "Kinect"
    fig, axes = plt.subplots(2, 4, figsize=(16, 7.5), sharey=True)
    for i, method in enumerate(run.methods):
        joints = [run.runs[(method, r.name)].joints for r in run.sequences]
        est = joint_angles(np.concatenate([to_convention(j, convention) for j in joints]))
        agreement = angle_agreement(est, ref)
        style = {"color": _COLOURS[i % len(_COLOURS)], "zorder": 3 + len(run.methods) - i}
        for k, (ax, name) in enumerate(zip(axes.ravel(), ANGLE_NAMES, strict=True)):
            # The first method (the tracker) is drawn on top of the others.
            mean, diff = (est[:, k] + ref[:, k]) / 2, est[:, k] - ref[:, k]
            ax.scatter(mean, diff, s=2, alpha=0.25, rasterized=True, **style)
            row = agreement[name]
            if row["bias_deg"] is None:
                continue
            ax.axhline(row["bias_deg"], lw=1.4, label=f"{method} {row['bias_deg']:+.1f}", **style)
            for limit in (row["loa_low_deg"], row["loa_high_deg"]):
                ax.axhline(limit, lw=1.0, ls=":", **style)
    for ax, name in zip(axes.ravel(), ANGLE_NAMES, strict=True):
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_title(name.replace("_", " "))
        ax.set_xlim(-5, 185)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=7, title="bias", title_fontsize=7)
    for ax in axes[:, 0]:
        ax.set_ylabel(f"estimate - {kind} (degrees)")
    for ax in axes[-1]:
        ax.set_xlabel(f"mean of estimate and {kind} (degrees)")
    frames = len(ref)
    fig.suptitle(
        f"Agreement with the {kind}: bias (solid) and 95% limits (dotted), {frames} frames"
    )
    fig.tight_layout(rect=(0, 0, 1, 0.96))
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def _label_image(points: np.ndarray, labels: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """Labelled points splatted (3 x 3) onto an RGB image."""
    palette = np.array(PART_COLOURS, dtype=np.uint8)
    image = np.zeros((*intrinsics.shape, 3), dtype=np.uint8)
    if len(points) == 0:
        return image
    uv = np.rint(project(points, intrinsics)).astype(int)
    order = np.argsort(-points[:, 2])  # far first, near drawn last
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            r, c = uv[order, 1] + dr, uv[order, 0] + dc
            ok = (r >= 0) & (r < intrinsics.height) & (c >= 0) & (c < intrinsics.width)
            lab = labels[order][ok]
            good = (lab >= 0) & (lab < len(palette))
            image[r[ok][good], c[ok][good]] = palette[lab[good]]
    return image


def _crop(images: list[np.ndarray], margin: int = 8) -> tuple[slice, slice]:
    occupied = np.zeros(images[0].shape[:2], dtype=bool)
    for im in images:
        occupied |= im.reshape(*im.shape[:2], -1).any(axis=-1)
    if not occupied.any():
        return slice(None), slice(None)
    rows, cols = np.nonzero(occupied)
    h, w = occupied.shape
    return (
        slice(max(rows.min() - margin, 0), min(rows.max() + margin, h)),
        slice(max(cols.min() - margin, 0), min(cols.max() + margin, w)),
    )


class observe_relabel:
    """Record the tracker's labels just before and after its geodesic relabelling.

    A debug hook from outside (the tracker does not expose these labels): while the
    context is open, :func:`posedrift.labelling.relabel` as called by
    :mod:`posedrift.tracking._tracker` is observed, and each call's ``(points,
    before, after)`` is appended to :attr:`calls`. Does nothing if the tracker
    cannot be observed.
    """

    def __init__(self) -> None:
        self.calls: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._module = None
        self._original = None

    def __enter__(self) -> observe_relabel:
        try:
            import posedrift.tracking._tracker as module
        except ImportError:
            return self
        original = getattr(module, "relabel", None)
        if original is None:
            return self
        calls = self.calls

        def observed(points, labels, *args, **kwargs):
            out = original(points, labels, *args, **kwargs)
            after = out[0] if isinstance(out, tuple) else out
            calls.append((np.array(points), np.array(labels), np.array(after)))
            return out

        self._module, self._original = module, original
        module.relabel = observed
        return self

    def __exit__(self, *exc) -> None:
        if self._module is not None:
            self._module.relabel = self._original


def label_figure(run, sequence: str, path: Path, frames: list[int], *, forest=None) -> Path | None:
    """Fig. 6: label maps: ground truth, the tracker's labels before and after the
    geodesic relabelling (:func:`relabel_snapshots`), and each method's labels."""
    plt = _pyplot()
    record = next(r for r in run.sequences if r.name == sequence)
    if record.reference.labels is None:
        return None
    palette = np.vstack([[0, 0, 0], np.array(PART_COLOURS, dtype=np.uint8)]).astype(np.uint8)
    rows = [("ground truth", [palette[record.reference.labels[t]] for t in frames])]
    blank = np.zeros((*record.intrinsics.shape, 3), dtype=np.uint8)
    snaps = run.runs[("cpd", sequence)].relabel if "cpd" in run.methods else {}
    if snaps:
        for k, title in ((1, "cpd: registered labels"), (2, "cpd: after relabelling")):
            rows.append(
                (
                    title,
                    [
                        _label_image(snaps[t][0], snaps[t][k], record.intrinsics)
                        if t in snaps
                        else blank
                        for t in frames
                    ],
                )
            )
    for method in run.methods:
        results = run.runs[(method, sequence)].results
        rows.append(
            (
                f"{method} (result)",
                [
                    _label_image(results[t].points, results[t].labels, record.intrinsics)
                    for t in frames
                ],
            )
        )
    fig, axes = plt.subplots(
        len(rows), len(frames), figsize=(2.3 * len(frames), 2.9 * len(rows)), squeeze=False
    )
    for j in range(len(frames)):
        rs, cs = _crop([r[1][j] for r in rows])
        for i, (title, images) in enumerate(rows):
            ax = axes[i, j]
            ax.imshow(images[j][rs, cs], interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if j == 0:
                ax.set_ylabel(title, fontsize=9)
            if i == 0:
                ax.set_title(f"frame {frames[j]}", fontsize=9)
    fig.suptitle(f"Body-part labels: {sequence}")
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def crossing_scores(joints: np.ndarray) -> np.ndarray:
    """How much the limbs cross, per frame: ``(T,)`` metres (larger is harder).

    For arms and legs, the amount by which the right hand (foot) lies on the left
    side of the left hand (foot), measured along the person's right-to-left axis
    (right hip to left hip), plus how close the two hands (feet) come; frames with
    crossed limbs score highest.
    """
    j = np.asarray(joints, dtype=float)
    across = j[:, JOINT_INDEX["left_hip"]] - j[:, JOINT_INDEX["right_hip"]]
    across /= np.maximum(np.linalg.norm(across, axis=1, keepdims=True), 1e-9)
    score = np.zeros(len(j))
    for limb in ("hand", "elbow", "foot", "knee"):
        d = j[:, JOINT_INDEX[f"left_{limb}"]] - j[:, JOINT_INDEX[f"right_{limb}"]]
        side = np.sum(d * across, axis=1)  # negative when crossed
        score += np.maximum(-side, 0.0) + 0.1 * np.exp(-np.linalg.norm(d, axis=1) / 0.1)
    return np.nan_to_num(score)


def hard_frames(run, sequence: str, count: int = 4, min_gap: int = 10) -> list[int]:
    """Frames with the most crossing limbs (ground truth), else with the largest errors."""
    record = next(r for r in run.sequences if r.name == sequence)
    score = crossing_scores(record.reference.joints)
    if not np.any(score > 0.05):
        errs = []
        for method in run.methods:
            e = np.linalg.norm(
                run.runs[(method, sequence)].joints - record.reference.joints, axis=2
            )
            errs.append(np.where(np.isfinite(e), e, 0.0).mean(axis=1))
        score = np.mean(np.stack(errs), axis=0)
    score = score.copy()
    score[0] = -np.inf  # the calibration frame is not a hard one
    chosen: list[int] = []
    for t in np.argsort(-score):
        if len(chosen) == count or not np.isfinite(score[t]):
            break
        if all(abs(int(t) - c) >= min_gap for c in chosen):
            chosen.append(int(t))
    return sorted(chosen) or [0]


def _draw_skeleton(
    ax, joints: np.ndarray, intrinsics: Intrinsics, colour: str, offset, style: str = "-"
) -> None:
    if not np.isfinite(joints).any():
        return
    uv = project(np.nan_to_num(joints, nan=0.0), intrinsics)
    uv[~np.isfinite(joints).all(axis=1)] = np.nan
    uv = uv - np.array([offset[1], offset[0]])
    for i, p in enumerate(JOINT_PARENTS):
        if p >= 0:
            ax.plot(uv[[i, p], 0], uv[[i, p], 1], style, color=colour, lw=1.6)
    ax.plot(uv[:, 0], uv[:, 1], "o", color=colour, ms=2.5)
    for side, marker in (("left", "s"), ("right", "^")):
        for name in (f"{side}_hand", f"{side}_foot"):
            ax.plot(*uv[JOINT_INDEX[name]], marker, color=colour, ms=4)


def overlay_figure(run, sequence: str, path: Path, frames: list[int]) -> Path | None:
    """Fig. 12: each method's skeleton (solid) and the reference (white) on the depth image."""
    plt = _pyplot()
    record = next(r for r in run.sequences if r.name == sequence)
    if record.frames is None:
        return None
    fig, axes = plt.subplots(
        len(run.methods),
        len(frames),
        figsize=(2.4 * len(frames), 3.0 * len(run.methods)),
        squeeze=False,
    )
    for j, t in enumerate(frames):
        depth = record.frames[t].depth
        rs, cs = _crop([depth > 0], margin=12)
        crop = depth[rs, cs]
        shown = np.where(crop > 0, crop, np.nan)
        for i, method in enumerate(run.methods):
            ax = axes[i, j]
            ax.imshow(shown, cmap="gray_r", interpolation="nearest", alpha=0.55)
            ax.set_facecolor("black")
            offset = (rs.start or 0, cs.start or 0)
            _draw_skeleton(
                ax, record.reference.joints[t], record.intrinsics, "lime", offset, style="--"
            )
            est = run.runs[(method, sequence)].results[t].joints
            _draw_skeleton(ax, est, record.intrinsics, _COLOURS[i % len(_COLOURS)], offset)
            ax.set_xlim(0, crop.shape[1])
            ax.set_ylim(crop.shape[0], 0)
            ax.set_xticks([])
            ax.set_yticks([])
            if j == 0:
                ax.set_ylabel(method, fontsize=10)
            if i == 0:
                ax.set_title(f"frame {t}", fontsize=9)
    ref = "ground truth" if record.reference.kind == "synthetic" else "Kinect reference"
    fig.suptitle(f"{sequence}: estimate (solid) and {ref} (green, dashed); ▲ right, ■ left")
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def write_figures(
    run, out_dir: str | Path, *, max_sequences: int = 3, forest=None, convention: str = "native"
) -> list[Path]:
    """Write Fig. 9, 6 and 12 for the first ``max_sequences`` sequences of a run, and
    the Bland-Altman plot of all of them (:func:`agreement_figure`).

    Returns
    -------
    list of Path
        The PNG files written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for record in run.sequences[:max_sequences]:
        name = _safe(record.name)
        written.append(angle_figure(run, record.name, out / f"fig9_angles_{name}.png"))
        frames = hard_frames(run, record.name)
        p = label_figure(run, record.name, out / f"fig6_labels_{name}.png", frames, forest=forest)
        if p is not None:
            written.append(p)
        p = overlay_figure(run, record.name, out / f"fig12_overlays_{name}.png", frames)
        if p is not None:
            written.append(p)
    written.append(agreement_figure(run, out / "bland_altman.png", convention=convention))
    return written
