"""Name maps from motion-capture rigs to the 15-joint skeleton, and units / up-axis detection.

Every rig maps its nodes to the 15 joints of ``METHOD.md`` section 2 the same way:

- ``shoulder`` is the glenohumeral joint (the upper-arm joint), never the clavicle;
  ``elbow`` the forearm joint; ``hand`` the wrist; ``hip`` the thigh joint; ``knee``
  the shank joint; ``foot`` the ankle.
- ``neck`` is the base of the neck, a few centimetres above the line of the shoulders:
  CMU original ``Neck`` (the upper-neck bone; ``lowerneck`` sits at chest level),
  cgspeed ``Neck1`` where present (its ``Neck`` is the original's ``lowerneck``,
  below the shoulders) else ``Neck``, CC_Base ``CC_Base_NeckTwist01`` (measured
  5-7 cm above the upper-arm joints on the development clips), game and Unreal rigs
  ``Neck`` / ``neck_01``.
- ``head`` is the centre of the head: the midpoint between the rig's head joint (at
  the skull base) and the head top. The head top is the head joint's ``End Site``
  (or a ``HeadTop_End``-like node) where the rig gives one; else (CC_Base) it is
  placed along the neck-to-head direction at ``HEAD_TOP_FRACTION`` times the
  distance head joint - pelvis centre plus the leg length (see :func:`map_positions`).
- ``torso`` is the midpoint of ``neck`` and the pelvis centre (mean of the hips).
- Extras: ``head_top``; hand tips (the middle finger's end, the hand's end site, or
  CC_Base ``Mid3`` extrapolated by one phalanx); toes (toe end site, or CC_Base
  ``MidToe1`` extrapolated by one toe segment).

Names match case-insensitively after dropping a namespace prefix (``mixamorig:``,
``Armature|``), so Mixamo files map through the cgspeed names.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from posedrift.skeleton import EXTRA_POINT_NAMES, JOINT_INDEX, JOINT_NAMES

HEAD_TOP_FRACTION = 0.129
"""Head top above the head joint, as a fraction of (head joint - pelvis centre
distance + leg length), when a rig gives no head top: with ankle height 0.039 H and
the head joint at about 0.89 H (Drillis & Contini), ``0.11 / 0.851``."""

# A candidate is a node name, or ("beyond", a, b): b + (b - a), one segment past b.
Candidate = str | tuple[str, str, str]

_REQUIRED = tuple(n for n in JOINT_NAMES if n != "torso")


@dataclass(frozen=True)
class RigMap:
    """How one rig's nodes give the 15 joints and the extra points.

    Parameters
    ----------
    name : str
        The rig's name (``"cmu-original"``, ``"cgspeed"``, ``"cc-base"``, ``"game"``,
        ``"unreal"`` or a user's).
    joints : mapping of str to tuple of candidates
        For each joint name except ``torso`` (and with ``head`` meaning the rig's head
        joint at the skull base), node names tried in order; the first found wins.
    extras : mapping of str to tuple of candidates
        The same for ``head_top``, ``left_hand_tip``, ``right_hand_tip``,
        ``left_toe``, ``right_toe`` (optional: absent extras are left out).
    """

    name: str
    joints: Mapping[str, tuple[Candidate, ...]]
    extras: Mapping[str, tuple[Candidate, ...]] = field(default_factory=dict)


def _sided(
    left: Mapping[str, tuple[Candidate, ...]], swap: tuple[tuple[str, str], ...]
) -> dict[str, tuple[Candidate, ...]]:
    """Left-side entries plus the right side made by replacing name fragments."""

    def mirror(c: Candidate) -> Candidate:
        if isinstance(c, tuple):
            return (c[0], *(mirror(x) for x in c[1:]))  # type: ignore[return-value]
        for a, b in swap:
            if a in c:
                return c.replace(a, b)
        return c

    out: dict[str, tuple[Candidate, ...]] = {}
    for key, cands in left.items():
        out[key] = cands
        if key.startswith("left_"):
            out["right_" + key[5:]] = tuple(mirror(c) for c in cands)
    return out


CMU_ORIGINAL = RigMap(
    "cmu-original",
    _sided(
        {
            "head": ("Head",),
            "neck": ("Neck",),
            "left_shoulder": ("LeftShoulder",),
            "left_elbow": ("LeftElbow",),
            "left_hand": ("LeftWrist",),
            "left_hip": ("LeftHip",),
            "left_knee": ("LeftKnee",),
            "left_foot": ("LeftAnkle",),
        },
        (("Left", "Right"),),
    ),
    _sided(
        {
            "head_top": ("Head/End Site",),
            "left_hand_tip": ("LFingers/End Site", "lhand/End Site", "LeftWrist/End Site"),
            "left_toe": ("LeftToe/End Site", "LeftToe"),
        },
        (("LFingers", "RFingers"), ("lhand", "rhand"), ("Left", "Right")),
    ),
)
"""The original 31-joint CMU skeleton (ASF converted to BVH)."""

CGSPEED = RigMap(
    "cgspeed",
    _sided(
        {
            "head": ("Head",),
            "neck": ("Neck1", "Neck"),
            "left_shoulder": ("LeftArm",),
            "left_elbow": ("LeftForeArm",),
            "left_hand": ("LeftHand",),
            "left_hip": ("LeftUpLeg",),
            "left_knee": ("LeftLeg",),
            "left_foot": ("LeftFoot",),
        },
        (("Left", "Right"),),
    ),
    _sided(
        {
            "head_top": ("Head/End Site", "HeadTop_End", "HeadTop_End/End Site"),
            "left_hand_tip": (
                "LeftHandMiddle4",
                "LeftHandMiddle3/End Site",
                "LeftHandIndex1/End Site",
                "LeftFingerBase/End Site",
                "LeftHand/End Site",
            ),
            "left_toe": ("LeftToe_End", "LeftToeBase/End Site", "LeftToeBase"),
        },
        (("Left", "Right"),),
    ),
)
"""The cgspeed (Bruce Hahne) CMU conversion; also Mixamo after prefix stripping."""

CC_BASE = RigMap(
    "cc-base",
    _sided(
        {
            "head": ("CC_Base_Head",),
            "neck": ("CC_Base_NeckTwist01",),
            "left_shoulder": ("CC_Base_L_Upperarm",),
            "left_elbow": ("CC_Base_L_Forearm",),
            "left_hand": ("CC_Base_L_Hand",),
            "left_hip": ("CC_Base_L_Thigh",),
            "left_knee": ("CC_Base_L_Calf",),
            "left_foot": ("CC_Base_L_Foot",),
        },
        (("_L_", "_R_"),),
    ),
    _sided(
        {
            "left_hand_tip": (("beyond", "CC_Base_L_Mid2", "CC_Base_L_Mid3"), "CC_Base_L_Hand"),
            "left_toe": (("beyond", "CC_Base_L_ToeBase", "CC_Base_L_MidToe1"),),
        },
        (("_L_", "_R_"),),
    ),
)
"""Reallusion Character Creator (CC3/CC4) ``CC_Base_*`` rig: no head top (estimated)."""

GAME = RigMap(
    "game",
    _sided(
        {
            "head": ("Head",),
            "neck": ("Neck",),
            "left_shoulder": ("UpperArm_L",),
            "left_elbow": ("LowerArm_L",),
            "left_hand": ("Hand_L",),
            "left_hip": ("UpperLeg_L",),
            "left_knee": ("LowerLeg_L",),
            "left_foot": ("Foot_L",),
        },
        (("_L", "_R"),),
    ),
    _sided(
        {
            "head_top": ("Head/End Site", "HeadTop_End", "Head_End", "Head_end/End Site"),
            "left_hand_tip": (
                "Middle3_L/End Site",
                "MiddleFinger3_L/End Site",
                "Hand_L/End Site",
                "Middle3_L",
            ),
            "left_toe": ("Toes_L/End Site", "Toe_L/End Site", "Toes_L", "Toe_L", "Foot_L/End Site"),
        },
        (("_L", "_R"),),
    ),
)
"""A common game rig (Unity humanoid style): ``UpperArm_L``, ``LowerArm_L``, ``UpperLeg_L``..."""

UNREAL = RigMap(
    "unreal",
    _sided(
        {
            "head": ("head",),
            "neck": ("neck_01",),
            "left_shoulder": ("upperarm_l",),
            "left_elbow": ("lowerarm_l",),
            "left_hand": ("hand_l",),
            "left_hip": ("thigh_l",),
            "left_knee": ("calf_l",),
            "left_foot": ("foot_l",),
        },
        (("_l", "_r"),),
    ),
    _sided(
        {
            "head_top": ("head/End Site",),
            "left_hand_tip": ("middle_03_l/End Site", "middle_03_l", "hand_l/End Site"),
            "left_toe": ("ball_l/End Site", "ball_l"),
        },
        (("_l", "_r"),),
    ),
)
"""The Unreal Engine mannequin (``upperarm_l``, ``thigh_l``, ``calf_l``, ``ball_l``...)."""

RIGS: tuple[RigMap, ...] = (CMU_ORIGINAL, CGSPEED, CC_BASE, GAME, UNREAL)
"""Known rigs, tried in this order when none is given."""


def normalize_name(name: str) -> str:
    """Lower case, without a namespace prefix (``mixamorig:Hips`` -> ``hips``)."""
    head, sep, tail = name.partition("/End Site")
    for mark in (":", "|"):
        head = head.rsplit(mark, 1)[-1]
    return (head + sep + tail).lower()


def _resolve(candidate: Candidate, lookup: Mapping[str, int]) -> tuple | None:
    """``("node", i)`` or ``("beyond", i, j)`` for a candidate present in the file."""
    if isinstance(candidate, tuple):
        a = lookup.get(normalize_name(candidate[1]))
        b = lookup.get(normalize_name(candidate[2]))
        return None if a is None or b is None else ("beyond", a, b)
    i = lookup.get(normalize_name(candidate))
    return None if i is None else ("node", i)


@dataclass(frozen=True)
class ResolvedRig:
    """A rig map resolved against one file's node names."""

    rig: RigMap
    joints: Mapping[str, tuple]
    extras: Mapping[str, tuple]

    @property
    def nodes(self) -> list[int]:
        """Every node index needed, sorted."""
        out: set[int] = set()
        for spec in (*self.joints.values(), *self.extras.values()):
            out.update(spec[1:])
        return sorted(out)


def resolve_rig(
    node_names: tuple[str, ...] | list[str],
    *,
    rig: str | RigMap | Mapping[str, str] | None = None,
    source: str = "<bvh>",
) -> ResolvedRig:
    """Find the rig map that fits ``node_names``.

    Parameters
    ----------
    node_names : sequence of str
        The file's node names (end sites as ``<parent>/End Site``).
    rig : str, RigMap, mapping or None
        A known rig's name, a :class:`RigMap`, a ``{joint name: node name}`` mapping
        for a custom rig, or None to try :data:`RIGS` in order.
    source : str
        The file, for messages.

    Raises
    ------
    ValueError
        If no rig maps every joint: the message lists the joints that were not
        found (for the rig that came closest) and the joint names the file holds.

    Examples
    --------
    >>> resolve_rig(["Hips", "LeftUpLeg"], source="a.bvh")
    Traceback (most recent call last):
    ...
    ValueError: a.bvh: cannot map the skeleton to the 15 joints ...
    """
    lookup: dict[str, int] = {}
    for i, name in enumerate(node_names):
        lookup.setdefault(normalize_name(name), i)
    if rig is None:
        candidates = list(RIGS)
    elif isinstance(rig, RigMap):
        candidates = [rig]
    elif isinstance(rig, str):
        known = {r.name: r for r in RIGS}
        if rig not in known:
            raise ValueError(
                f"The 'rig' parameter must be one of {sorted(known)}, a RigMap or a mapping. "
                f"Got {rig!r} instead."
            )
        candidates = [known[rig]]
    elif isinstance(rig, Mapping):
        unknown = sorted(set(rig) - set(JOINT_NAMES) - set(EXTRA_POINT_NAMES))
        if unknown:
            raise ValueError(
                f"The 'rig' mapping has keys that are not joint or extra-point names: {unknown}."
            )
        joints = {k: (v,) for k, v in rig.items() if k in JOINT_INDEX}
        extras = {k: (v,) for k, v in rig.items() if k not in JOINT_INDEX}
        candidates = [RigMap("custom", joints, extras)]
    else:
        raise ValueError(
            f"The 'rig' parameter must be a str, a RigMap, a mapping or None. "
            f"Got {type(rig).__name__} instead."
        )
    best: tuple[int, RigMap, list[str]] | None = None
    for candidate in candidates:
        found: dict[str, tuple] = {}
        missing: list[str] = []
        for joint in _REQUIRED:
            spec = next(
                (r for c in candidate.joints.get(joint, ()) if (r := _resolve(c, lookup))), None
            )
            if spec is None:
                missing.append(joint)
            else:
                found[joint] = spec
        if not missing:
            extras = {}
            for extra, cands in candidate.extras.items():
                spec = next((r for c in cands if (r := _resolve(c, lookup))), None)
                if spec is not None:
                    extras[extra] = spec
            return ResolvedRig(candidate, found, extras)
        if best is None or len(missing) < len(best[2]):
            best = (len(found), candidate, missing)
    assert best is not None
    _, closest, missing = best
    wanted = {
        j: [c if isinstance(c, str) else c[2] for c in closest.joints.get(j, ())] for j in missing
    }
    joint_names = [n for n in node_names if not n.endswith("/End Site")]
    shown = ", ".join(joint_names[:80]) + (" ..." if len(joint_names) > 80 else "")
    raise ValueError(
        f"{source}: cannot map the skeleton to the 15 joints (closest rig {closest.name!r}); "
        f"missing joints: {', '.join(f'{j} (looked for {wanted[j]})' for j in missing)}. "
        f"The file's joints are: {shown}. Pass rig={{joint name: node name}} for this rig."
    )


def map_positions(resolved: ResolvedRig, positions: np.ndarray) -> tuple[np.ndarray, dict]:
    """The 15 joints and the extras from node positions (file units and axes).

    Parameters
    ----------
    resolved : ResolvedRig
    positions : (T, N, 3) float
        World positions of every node of the file, or of ``resolved.nodes`` only
        when ``N == len(resolved.nodes)`` (then indices refer to that subset).

    Returns
    -------
    joints : (T, 15, 3) float
    extras : dict of str to (T, 3) float
    """
    nodes = resolved.nodes
    slot = {i: k for k, i in enumerate(nodes)} if positions.shape[1] == len(nodes) else None

    def get(spec: tuple) -> np.ndarray:
        idx = [slot[i] if slot is not None else i for i in spec[1:]]
        if spec[0] == "node":
            return positions[:, idx[0]]
        a, b = positions[:, idx[0]], positions[:, idx[1]]
        return b + (b - a)

    t = positions.shape[0]
    joints = np.empty((t, len(JOINT_NAMES), 3))
    for name, spec in resolved.joints.items():
        joints[:, JOINT_INDEX[name]] = get(spec)
    extras = {name: get(spec) for name, spec in resolved.extras.items()}
    neck = joints[:, JOINT_INDEX["neck"]]
    skull = joints[:, JOINT_INDEX["head"]].copy()
    pelvis = 0.5 * (joints[:, JOINT_INDEX["left_hip"]] + joints[:, JOINT_INDEX["right_hip"]])
    if "head_top" not in extras:
        # Head top along neck -> head joint, at a fraction of a pose-independent
        # length (head joint - pelvis, plus the mean leg), measured on frame 0.
        leg = 0.0
        for side in ("left", "right"):
            hip, knee, foot = (
                joints[0, JOINT_INDEX[f"{side}_{j}"]] for j in ("hip", "knee", "foot")
            )
            leg += 0.5 * (np.linalg.norm(knee - hip) + np.linalg.norm(foot - knee))
        length = HEAD_TOP_FRACTION * (np.linalg.norm(skull[0] - pelvis[0]) + leg)
        direction = skull - neck
        norm = np.linalg.norm(direction, axis=-1, keepdims=True)
        direction = direction / np.where(norm > 0, norm, 1.0)
        extras["head_top"] = skull + length * direction
    joints[:, JOINT_INDEX["head"]] = 0.5 * (skull + extras["head_top"])
    joints[:, JOINT_INDEX["torso"]] = 0.5 * (neck + pelvis)
    return joints, extras


UNIT_SCALES: Mapping[str, float] = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "inch": 0.0254,
    "cmu": 0.0254 / 0.45,
}
"""Candidate file units, in metres per file unit (``cmu``: the CMU ASF scale)."""


def stature_estimate(joints: np.ndarray, extras: Mapping[str, np.ndarray]) -> float:
    """A pose-independent stature from frame 0's bone lengths, in the joints' units.

    Head top to pelvis centre (straight-line distance) plus the mean leg length
    (hip-knee plus knee-ankle) plus an ankle height of 0.039 H: ``(a + b) / 0.961``.
    """
    j = joints[0]
    pelvis = 0.5 * (j[JOINT_INDEX["left_hip"]] + j[JOINT_INDEX["right_hip"]])
    leg = 0.0
    for side in ("left", "right"):
        hip, knee, foot = (j[JOINT_INDEX[f"{side}_{n}"]] for n in ("hip", "knee", "foot"))
        leg += 0.5 * (np.linalg.norm(knee - hip) + np.linalg.norm(foot - knee))
    top = extras["head_top"][0] if "head_top" in extras else j[JOINT_INDEX["head"]]
    return float((np.linalg.norm(top - pelvis) + leg) / 0.961)


def detect_units(stature: float, *, source: str = "<bvh>") -> tuple[str, float]:
    """The unit whose scale makes ``stature`` closest to 1.75 m (log ratio).

    Raises
    ------
    ValueError
        If even the best unit gives a stature outside 0.9-2.6 m.

    Examples
    --------
    >>> detect_units(172.0)
    ('cm', 0.01)
    >>> detect_units(30.0)[0]
    'cmu'
    """
    if not (np.isfinite(stature) and stature > 0):
        raise ValueError(f"{source}: the skeleton has no height (stature {stature!r}).")
    name = min(UNIT_SCALES, key=lambda u: abs(np.log(stature * UNIT_SCALES[u] / 1.75)))
    metres = stature * UNIT_SCALES[name]
    if not 0.9 <= metres <= 2.6:
        raise ValueError(
            f"{source}: cannot tell the units: the skeleton measures {stature:.4g} file units "
            f"tall, which is no human height in any of {sorted(UNIT_SCALES)} (closest: "
            f"{metres:.2f} m in {name}). Pass scale= (metres per file unit)."
        )
    return name, UNIT_SCALES[name]


def detect_up_axis(joints: np.ndarray) -> np.ndarray:
    """The file's up direction as a signed unit axis, ``(3,)``.

    The axis along which the head minus the mean of the feet is largest, taken as the
    median over frames (robust to a few frames lying or upside-down).
    """
    head = joints[:, JOINT_INDEX["head"]]
    feet = 0.5 * (joints[:, JOINT_INDEX["left_foot"]] + joints[:, JOINT_INDEX["right_foot"]])
    d = np.median(head - feet, axis=0)
    axis = int(np.argmax(np.abs(d)))
    up = np.zeros(3)
    up[axis] = np.sign(d[axis]) or 1.0
    return up
