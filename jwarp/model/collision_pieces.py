"""The convex pieces of a robot's collision geometry (``RobotModel.collision_pieces``, JSON
key ``"collision_pieces"``; docs/robot_schema.md).

A :class:`ConvexPiece` is a sphere-swept convex polytope fixed to one frame: the set
``{v + u : v in conv(vertices), |u| <= radius}``. A sphere is one vertex and its radius,
a capsule the two ends of its segment and its radius, a box its 8 corners, a mesh the
vertices of its convex hull. The pieces of an imported URDF contain its collision geometry
(:func:`jwarp.importers.collision_pieces.pieces_from_geometries`): a certificate that finds
every piece free of the world proves the real meshes free, not only the collision spheres.

The pieces stand for the spheres they were made beside: ``sphere_count`` and
``sphere_digest`` (:func:`sphere_digest` of the first ``sphere_count`` spheres) identify
them. Spheres appended later (an attached object) are not among the pieces:
:meth:`CollisionPieces.extra_spheres` lists them; spheres edited later (a radius, a centre)
make that answer None, unless the model is stamped again (:func:`stamp_pieces`, as the
import does once its spheres are final).

numpy only (no trimesh): the model layer.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.utils.checks import check_int

if TYPE_CHECKING:
    from jwarp.model import RobotModel

__all__ = ["ConvexPiece", "CollisionPieces", "sphere_digest", "stamp_pieces", "check_pieces",
           "pieces_to_dict", "pieces_from_dict"]

KEY = "collision_pieces"


@dataclass
class ConvexPiece:
    """One convex piece (:mod:`jwarp.model.collision_pieces`): the set
    ``{v + u : v in conv(vertices), |u| <= radius}``; ``frame`` (frame index), ``vertices`` (V, 3)
    [m] in the frame's coordinates (V >= 1), ``radius`` [m] >= 0 swept around their convex
    hull, ``source`` what it was made of (e.g. ``"panda_link5 <collision> 1 mesh hull"``)."""

    frame: int
    vertices: np.ndarray
    radius: float = 0.0
    source: str = ""


@dataclass
class CollisionPieces:
    """The convex pieces of a robot's collision geometry and the spheres they were made
    beside (:mod:`jwarp.model.collision_pieces`).

    pieces: the pieces, in the order of the collision geometry.
    sphere_count: how many of the model's spheres (its first ones) the pieces stand for.
    sphere_digest: :func:`sphere_digest` of those spheres.
    method: how the pieces were made (one line).
    """

    pieces: list[ConvexPiece]
    sphere_count: int
    sphere_digest: str
    method: str = ""

    def extra_spheres(self, model: RobotModel) -> list[int] | None:
        """Indices of ``model``'s spheres that the pieces do not stand for: those after
        ``sphere_count`` when the first ``sphere_count`` spheres are still the ones the
        pieces were made beside (same frames, centres and radii: spheres appended later,
        e.g. an attached object); None when they are not (spheres edited or removed: the
        pieces cannot be trusted to stand for them)."""
        spheres = list(model.spheres)
        if len(spheres) < self.sphere_count:
            return None
        if sphere_digest(spheres[:self.sphere_count]) != self.sphere_digest:
            return None
        return list(range(self.sphere_count, len(spheres)))

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                              np.ndarray]:
        """The pieces as flat arrays (K pieces, V vertices in all): frame (K,) int32,
        vstart (K + 1,) int32 (piece k's vertices are ``vertices[vstart[k]:vstart[k + 1]]``),
        vertices (V, 3) float64 [m] in their frames, radius (K,) float64 [m], centre (K, 3)
        and bound (K,) float64 [m]: a sphere holding piece k, its radius included (centre
        the middle of the vertices' bounding box, bound the farthest vertex + radius)."""
        k = len(self.pieces)
        frame = np.array([p.frame for p in self.pieces], np.int32).reshape(k)
        counts = np.array([len(p.vertices) for p in self.pieces], np.int64).reshape(k)
        vstart = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
        vertices = (np.concatenate([np.asarray(p.vertices, np.float64).reshape(-1, 3)
                                    for p in self.pieces]) if k else np.zeros((0, 3)))
        radius = np.array([p.radius for p in self.pieces], np.float64).reshape(k)
        centre = np.zeros((k, 3))
        bound = np.zeros(k)
        for i, p in enumerate(self.pieces):
            v = np.asarray(p.vertices, np.float64).reshape(-1, 3)
            centre[i] = 0.5 * (v.min(axis=0) + v.max(axis=0))
            bound[i] = float(np.linalg.norm(v - centre[i], axis=1).max()) + float(p.radius)
        return frame, vstart, vertices, radius, centre, bound


def sphere_digest(spheres: Sequence[Any]) -> str:
    """sha256 (hex) of a list of :class:`~jwarp.model.Sphere`: the bytes of their frames
    (n,) int64, centres (n, 3) float64 [m] and radii (n,) float64 [m], in that order."""
    n = len(spheres)
    f = np.array([int(s.frame) for s in spheres], np.int64).reshape(n)
    p = np.array([np.asarray(s.position, np.float64).reshape(3) for s in spheres],
                 np.float64).reshape(n, 3)
    r = np.array([float(s.radius) for s in spheres], np.float64).reshape(n)
    h = hashlib.sha256()
    for a in (f, p, r):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def stamp_pieces(model: RobotModel) -> Any:
    """A copy of ``model`` (a :class:`~jwarp.model.RobotModel`) whose pieces stand for all
    of its current spheres (``sphere_count`` and ``sphere_digest`` of them): for an import
    whose spheres were edited after the pieces were made (tightened at the home, certified
    again), called once they are final. A model without pieces is returned as it is."""
    cp = getattr(model, "collision_pieces", None)
    if cp is None:
        return model
    new = CollisionPieces(pieces=cp.pieces, sphere_count=len(model.spheres),
                          sphere_digest=sphere_digest(model.spheres), method=cp.method)
    return model.copy(collision_pieces=new)


# ------------------------------------------------------------------ checks
def _vertices(v: Any, where: str) -> np.ndarray:
    """``v`` as a (V, 3) float64 array of finite numbers, V >= 1; ValueError/TypeError
    naming ``where``."""
    if isinstance(v, (bool, np.bool_, str, bytes, dict)):
        raise TypeError(f"{where}: expected a list of [x, y, z], got {type(v).__name__}")
    try:
        a = np.asarray(v)
    except (TypeError, ValueError):
        raise TypeError(f"{where}: expected a list of [x, y, z]") from None
    if a.ndim != 2 or a.shape[1] != 3 or a.dtype.kind not in "iuf":
        if a.size == 0:
            raise ValueError(f"{where}: empty (a piece needs at least one vertex)")
        raise TypeError(f"{where}: expected a list of [x, y, z], got shape {a.shape}"
                        + ("" if a.dtype.kind in "iuf" else f" of {a.dtype.kind!r} values"))
    if len(a) == 0:
        raise ValueError(f"{where}: empty (a piece needs at least one vertex)")
    a = a.astype(np.float64)
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        raise ValueError(f"{where}[{int(np.argmax(bad))}]: not finite: "
                         f"{a[int(np.argmax(bad))].tolist()}")
    return a


def _radius(v: Any, where: str) -> float:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer,
                                                             np.floating)):
        raise TypeError(f"{where}: expected a number [m], got {type(v).__name__}")
    x = float(v)
    if not math.isfinite(x) or x < 0:
        raise ValueError(f"{where}: expected a finite distance >= 0 [m], got {v!r}")
    return x


def _count(v: Any, where: str) -> int:
    return check_int(v, where, 0)


def _text(v: Any, where: str) -> str:
    if not isinstance(v, str):
        raise TypeError(f"{where}: expected a string, got {type(v).__name__}")
    return v


def check_pieces(cp: Any, n_frames: int) -> None:
    """Check ``cp`` (a :class:`CollisionPieces`) against a robot of ``n_frames`` frames and
    store its numbers as Python ints/floats and (V, 3) float64 arrays; ValueError/TypeError
    naming the key and the index (``collision_pieces.pieces[3].vertices: ...``)."""
    if not isinstance(cp, CollisionPieces):
        raise TypeError(f"{KEY}: expected a CollisionPieces or None, got "
                        f"{type(cp).__name__}")
    if not isinstance(cp.pieces, list):
        raise TypeError(f"{KEY}.pieces: expected a list, got {type(cp.pieces).__name__}")
    for k, p in enumerate(cp.pieces):
        w = f"{KEY}.pieces[{k}]"
        if not isinstance(p, ConvexPiece):
            raise TypeError(f"{w}: expected a ConvexPiece, got {type(p).__name__}")
        if (isinstance(p.frame, (bool, np.bool_)) or not isinstance(p.frame, (int, np.integer))
                or not 0 <= p.frame < n_frames):
            raise ValueError(f"{w}.frame: frame index {p.frame!r} out of range "
                             f"[0, {n_frames})")
        p.frame = int(p.frame)
        p.vertices = _vertices(p.vertices, f"{w}.vertices")
        p.radius = _radius(p.radius, f"{w}.radius")
        p.source = _text(p.source, f"{w}.source")
    cp.sphere_count = _count(cp.sphere_count, f"{KEY}.sphere_count")
    cp.sphere_digest = _text(cp.sphere_digest, f"{KEY}.sphere_digest")
    cp.method = _text(cp.method, f"{KEY}.method")


# ------------------------------------------------------------------ JSON
def pieces_to_dict(cp: CollisionPieces, frame_names: Sequence[str]) -> dict[str, Any]:
    """The JSON object of ``cp`` (key ``"collision_pieces"`` of the robot document; frames
    by name, vertices [m] as written, exactly)."""
    return {"pieces": [{"frame": frame_names[p.frame],
                        "vertices": np.asarray(p.vertices, np.float64).tolist(),
                        "radius": float(p.radius), "source": p.source} for p in cp.pieces],
            "sphere_count": int(cp.sphere_count), "sphere_digest": cp.sphere_digest,
            "method": cp.method}


def _frame(v: Any, frame_names: Sequence[str], where: str) -> int:
    """A frame given by name or index (docs/robot_schema.md) as its index."""
    if isinstance(v, str):
        if v not in frame_names:
            raise ValueError(f"{where}: unknown frame '{v}'")
        return list(frame_names).index(v)
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"{where}: expected a frame name or index, got {v!r}")
    if not 0 <= v < len(frame_names):
        raise ValueError(f"{where}: frame index {v} out of range [0, {len(frame_names)})")
    return int(v)


def pieces_from_dict(doc: Any, frame_names: Sequence[str]) -> CollisionPieces | None:
    """A :class:`CollisionPieces` from its JSON object (None: None); ``frame_names`` the
    robot's frames. ValueError/TypeError naming the key and the index."""
    if doc is None:
        return None
    if not isinstance(doc, dict):
        raise TypeError(f"{KEY}: expected an object, got {type(doc).__name__}")
    unknown = set(doc) - {"pieces", "sphere_count", "sphere_digest", "method"}
    if unknown:
        raise ValueError(f"{KEY}: unknown keys {sorted(unknown)}")
    for key in ("pieces", "sphere_count", "sphere_digest"):
        if key not in doc:
            raise ValueError(f"{KEY}.{key}: missing")
    items = doc["pieces"]
    if not isinstance(items, list):
        raise TypeError(f"{KEY}.pieces: expected a list, got {type(items).__name__}")
    pieces = []
    for k, d in enumerate(items):
        w = f"{KEY}.pieces[{k}]"
        if not isinstance(d, dict):
            raise TypeError(f"{w}: expected an object, got {type(d).__name__}")
        unknown = set(d) - {"frame", "vertices", "radius", "source"}
        if unknown:
            raise ValueError(f"{w}: unknown keys {sorted(unknown)}")
        for key in ("frame", "vertices"):
            if key not in d:
                raise ValueError(f"{w}.{key}: missing")
        pieces.append(ConvexPiece(frame=_frame(d["frame"], frame_names, f"{w}.frame"),
                                  vertices=_vertices(d["vertices"], f"{w}.vertices"),
                                  radius=_radius(d.get("radius", 0.0), f"{w}.radius"),
                                  source=_text(d.get("source", ""), f"{w}.source")))
    cp = CollisionPieces(pieces=pieces, sphere_count=doc["sphere_count"],
                         sphere_digest=doc["sphere_digest"], method=doc.get("method", ""))
    check_pieces(cp, len(frame_names))
    return cp
