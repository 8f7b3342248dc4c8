"""Where a linkage's parts are, in the world frame (m): what the drawing and the animation
place.

A [`Layout`][jaxcrank.views.geometry.Layout] is the static part (each body's points and
the shape drawn for it, each joint's sides and clearance); body frame poses come from the
assembly at a driver angle ([`assembled_poses`][jaxcrank.views.geometry.assembled_poses])
or from a run's columns ([`poses_from_columns`][jaxcrank.views.geometry.poses_from_columns]);
[`place`][jaxcrank.views.geometry.place] puts body points into the world. NumPy only:
nothing here is traced.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..physics.linkage import GROUND

#: the shapes a body is drawn as: two or more points on a line (a bar), three or more
#: points off a line (a plate), a single point (a block)
SHAPES = ("bar", "plate", "block")


def _number(v) -> float:
    return float(np.asarray(v, dtype=float))


def _xy(point) -> np.ndarray:
    return np.array([_number(point.x), _number(point.y)])


@dataclasses.dataclass(frozen=True)
class Part:
    """How one body is drawn.

    Attributes:
        body: its name.
        points: its named points in its frame, m.
        centre_of_mass: in its frame, m.
        shape: one of ``SHAPES``: ``"bar"``, ``"plate"``, ``"block"``.
        outline: in its frame, m: a bar's two end points, a plate's convex hull
            (counter-clockwise), a block's centre.
    """

    body: str
    points: dict[str, np.ndarray]
    centre_of_mass: np.ndarray
    shape: str
    outline: np.ndarray


@dataclasses.dataclass(frozen=True)
class JointSketch:
    """One joint as drawn.

    Attributes:
        name: the joint's name.
        kind: ``"revolute"`` or ``"prismatic"``.
        hole: ``(body, point)`` of the hole (a revolute joint) or of the guide's line
            (a prismatic one); body ``"ground"`` for a fixed part.
        pin: ``(body, point)`` of the pin, or of the sliding point.
        clearance: the joint law's clearance, m; ``None`` for an ideal joint.
        law: the law's name.
        direction: a prismatic joint's axis in the guide body's frame, rad (0 for a
            revolute joint).
        angle: a prismatic joint's held angle, the sliding body's less the guide body's,
            rad (0 for a revolute joint).
        wear: a worn joint's profiles ``(hole, pin)``, each the Fourier coefficients of its
            wear depth in its own body's frame (m; [`jaxcrank.physics.wear.Worn`][]); ``None``
            for a joint that does not wear.
    """

    name: str
    kind: str
    hole: tuple[str, str]
    pin: tuple[str, str]
    clearance: float | None
    law: str
    direction: float = 0.0
    angle: float = 0.0
    wear: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def worn(self) -> bool:
        """Whether the joint has worn: a wear profile that is not all zero (a new worn joint is round)."""
        return self.wear is not None and any(bool(np.any(profile)) for profile in self.wear)


@dataclasses.dataclass(frozen=True)
class Layout:
    """What is drawn of a linkage, apart from where its bodies are.

    Attributes:
        name: the linkage's label.
        parts: per moving body.
        ground: the ground's points, m.
        joints: per joint, in name order.
        driven: the body the driver turns.
    """

    name: str
    parts: dict[str, Part]
    ground: dict[str, np.ndarray]
    joints: tuple[JointSketch, ...]
    driven: str


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull of 2D points, counter-clockwise (Andrew's monotone chain)."""
    pts = sorted(set(map(tuple, np.round(points, 12))))
    if len(pts) < 3:
        return np.array(pts)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def _part(name: str, body) -> Part:
    points = {p: _xy(v) for p, v in body.points.items()}
    com = _xy(body.centre_of_mass)
    arr = np.array(list(points.values())) if points else com[None]
    span = float(np.max(np.ptp(arr, axis=0))) if len(arr) > 1 else 0.0
    if span <= 1e-12:
        return Part(name, points, com, "block", arr.mean(axis=0))
    hull = _hull(arr)
    # the area of the hull against its span: points off the line by less than 1 % of the span make a bar
    area = 0.5 * abs(float(np.sum(hull[:, 0] * np.roll(hull[:, 1], -1) - np.roll(hull[:, 0], -1) * hull[:, 1])))
    if len(hull) < 3 or area < 1e-2 * span * span:
        d = arr - arr.mean(axis=0)
        axis = np.linalg.svd(d, full_matrices=False)[2][0]
        s = d @ axis
        ends = arr[[int(np.argmin(s)), int(np.argmax(s))]]
        return Part(name, points, com, "bar", ends)
    return Part(name, points, com, "plate", hull)


def layout(mech) -> Layout:
    """The [`Layout`][jaxcrank.views.geometry.Layout] of a mechanism (a preset or a written-out
    linkage)."""
    lk = mech.linkage()
    parts = {b: _part(b, body) for b, body in sorted(lk.bodies.items())}
    joints = []
    for j, conn in sorted(lk.connections.items()):
        law = lk.joints[j]
        hole, pin = conn.sites()
        c = None if law.ideal else _number(law.clearance)
        direction = _number(conn.direction) if conn.kind == "prismatic" else 0.0
        held = _number(conn.angle) if conn.kind == "prismatic" else 0.0
        sides = (hole.body, hole.point), (pin.body, pin.point)
        wear = (np.asarray(law.hole_wear), np.asarray(law.pin_wear)) if hasattr(law, "hole_wear") else None
        joints.append(JointSketch(j, conn.kind, *sides, c, law.name, direction, held, wear))
    ground = {p: _xy(v) for p, v in lk.ground.items()}
    return Layout(lk.name, parts, ground, tuple(joints), lk.driver.body)


def gap(joint: JointSketch, directions, hole_angle=0.0, pin_angle=0.0) -> np.ndarray:
    """How far the pin's centre can move from the hole's in the world ``directions`` (rad) before
    the surfaces touch, m: the clearance plus, for a worn joint, the hole's wear depth at that
    direction in the hole body's frame (the body at ``hole_angle``, rad) and the pin's in the pin
    body's (at ``pin_angle``, rad). Broadcasts ``directions`` against the angles."""
    from ..physics.wear import profile_on_grid

    phi = np.asarray(directions, dtype=float)
    c = 0.0 if joint.clearance is None else joint.clearance
    if joint.wear is None:
        return np.full(np.broadcast(phi, np.asarray(hole_angle), np.asarray(pin_angle)).shape, c)
    hole, pin = joint.wear
    depth_h = np.asarray(profile_on_grid(hole, phi - np.asarray(hole_angle, dtype=float)))
    depth_p = np.asarray(profile_on_grid(pin, phi - np.asarray(pin_angle, dtype=float)))
    return c + depth_h + depth_p


def body_angle(cols, body: str, i=slice(None)) -> np.ndarray:
    """A body's angle at the samples ``i`` of a run's columns (``<body>_angle``, deg), rad; 0 for
    the ground, which has no column."""
    key = f"{body}_angle"
    if key in cols:
        return np.radians(np.asarray(cols[key], dtype=float)[i])
    return np.zeros_like(np.asarray(cols["t"], dtype=float)[i])


def assembled_poses(mech, angle=None) -> dict[str, np.ndarray]:
    """Each body frame's pose (x, y in m, angle in rad) in the ideal mechanism at the
    driver's ``angle`` (rad; default its initial angle): shape (3,) per body, or (n, 3)
    for an array of n angles (NaN where the linkage does not assemble at an angle).

    Raises:
        ParameterError: a linkage that cannot be assembled at its initial angle (from
            [`jaxcrank.physics.compiled.compile_model`][]).
    """

    from ..physics.compiled import compile_model

    model = compile_model(mech)
    phi = _number(model.linkage.driver.initial_angle) if angle is None else angle
    phi = np.asarray(phi, dtype=float)
    poses = np.asarray(_poses_at(model, phi.reshape(-1)))
    if phi.ndim == 0:
        poses = poses[0]
    return {b: poses[..., i, :] for i, b in enumerate(model.tree.bodies)}


def _poses_at(model, phis):
    import jax

    from ..physics.kinematics import ideal_poses

    global _POSES
    if _POSES is None:
        _POSES = jax.jit(jax.vmap(ideal_poses, in_axes=(None, 0)))
    return _POSES(model, phis)


_POSES = None  # the jitted, vmapped ideal poses (one program per structure)


def poses_from_columns(cols: dict, mech, prefix: str = "") -> dict[str, np.ndarray]:
    """Each body frame's pose (x, y in m, angle in rad), shape (n, 3), from a run's
    centre-of-mass columns ([`jaxcrank.analysis.outputs.trajectory`][]: ``<body>_x``,
    ``<body>_y`` in m, ``<body>_angle`` in deg); ``prefix="ideal_"``: the ideal mechanism's.

    Raises:
        KeyError: a column the mechanism's bodies need is missing (names it).
    """
    out = {}
    for b, part in layout(mech).parts.items():
        names = [f"{prefix}{b}_{k}" for k in ("x", "y", "angle")]
        missing = [n for n in names if n not in cols]
        if missing:
            raise KeyError(f"the run has no column {missing[0]!r}: is it a run of this mechanism?")
        x, y = np.asarray(cols[names[0]], dtype=float), np.asarray(cols[names[1]], dtype=float)
        angle = np.radians(np.asarray(cols[names[2]], dtype=float))
        c, s = np.cos(angle), np.sin(angle)
        cx, cy = part.centre_of_mass
        out[b] = np.stack([x - (c * cx - s * cy), y - (s * cx + c * cy), angle], axis=-1)
    return out


def place(local, pose) -> np.ndarray:
    """Body-frame points ``local`` (m, shape (..., 2)) in the world (m) for the frame's
    ``pose`` (x, y, angle: shape (3,), or (n, 3) for n instants, giving (n, ..., 2))."""
    local = np.asarray(local, dtype=float)
    pose = np.asarray(pose, dtype=float)
    if pose.ndim == 1:
        c, s = math.cos(pose[2]), math.sin(pose[2])
        rot = np.array([[c, -s], [s, c]])
        return local @ rot.T + pose[:2]
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # (n, 2, 2)
    flat = local.reshape(-1, 2)
    world = np.einsum("nij,kj->nki", rot, flat) + pose[:, None, :2]
    return world.reshape((pose.shape[0],) + local.shape)


def site(lay: Layout, poses: dict, where: tuple[str, str]) -> np.ndarray:
    """A body point's (or a ground point's) world position, m: (2,) or (n, 2) as the poses."""
    body, point = where
    if body == GROUND:
        p = lay.ground[point]
        any_pose = next(iter(poses.values()))
        return p if np.ndim(any_pose) == 1 else np.broadcast_to(p, (np.shape(any_pose)[0], 2))
    return place(lay.parts[body].points[point], poses[body])


def angle_of(poses: dict, body: str) -> np.ndarray | float:
    """A body's frame angle (rad; 0 for the ground), as the poses (one or n instants)."""
    if body == GROUND:
        any_pose = next(iter(poses.values()))
        return 0.0 if np.ndim(any_pose) == 1 else np.zeros(np.shape(any_pose)[0])
    return poses[body][..., 2]


def joint_positions(lay: Layout, poses: dict) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per joint, the world positions of its hole (guide) point and its pin (sliding) point, m."""
    return {j.name: (site(lay, poses, j.hole), site(lay, poses, j.pin)) for j in lay.joints}


def extent(lay: Layout, poses: dict) -> tuple[np.ndarray, np.ndarray]:
    """The lower-left and upper-right corners (m) of every point of the linkage, over every
    instant of ``poses``."""
    pts = [np.reshape(p, (-1, 2)) for p in lay.ground.values()]
    for b, part in lay.parts.items():
        local = np.array(list(part.points.values()) + [part.centre_of_mass])
        pts.append(np.reshape(place(local, poses[b]), (-1, 2)))
    allp = np.concatenate(pts)
    return allp.min(axis=0), allp.max(axis=0)
