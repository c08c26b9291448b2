"""The convex pieces of an imported robot's collision geometry
(:class:`~jwarp.model.CollisionPieces`, ``RobotModel.collision_pieces``;
docs/robot_schema.md).

:func:`pieces_from_geometries` makes one piece per collision geometry of the importer
(:class:`~jwarp.importers.urdf.CollisionGeometry`: URDF ``<collision>`` elements, MJCF
collision geoms), in its link's frame, posed by the geometry's origin, each containing
the geometry (never smaller):

* mesh: the vertices of the convex hull of the scaled mesh (a flat or degenerate mesh:
  its vertices themselves, whose hull is the same set); an MJCF ellipsoid (a scaled
  icosphere inscribed in it) grown until its hull holds the ellipsoid;
* box: its 8 corners; sphere: its centre and radius; capsule: the two ends of its segment
  (length along z) and its radius;
* cylinder: two regular 32-gons at z = +-length/2 circumscribing its circles (corner
  radius ``r / cos(pi / 32)``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from jwarp.model import RobotModel
from jwarp.model.collision_pieces import CollisionPieces, ConvexPiece, sphere_digest

__all__ = ["pieces_from_geometries", "geometry_piece", "hull_vertices", "CYLINDER_SIDES",
           "METHOD"]

#: sides of the polygons of a cylinder's piece
CYLINDER_SIDES = 32
#: the ``method`` of the pieces :func:`pieces_from_geometries` makes
METHOD = (f"convex hulls of the collision geometry (meshes' hull vertices, box corners, "
          f"sphere and capsule centres with their radius, {CYLINDER_SIDES}-gon cylinders "
          f"circumscribing the circles)")


def _get(g: Any, key: str) -> Any:
    return g.get(key) if isinstance(g, dict) else getattr(g, key, None)


def _posed(vertices: np.ndarray, origin: Any) -> np.ndarray:
    """(V, 3) ``vertices`` [m] of a geometry's frame in its link's frame (``origin``:
    the (4, 4) pose of the geometry in the link, None: identity)."""
    from jwarp.importers.spheres import _origin

    T = _origin(origin)
    return vertices @ T[:3, :3].T + T[:3, 3]


def _size(size: Any, n: int, kind: str) -> np.ndarray:
    """``size`` as ``n`` finite numbers >= 0 [m] (ValueError naming the kind)."""
    s = np.asarray(size if size is not None else [], np.float64).reshape(-1)
    if s.size != n or not np.all(np.isfinite(s)) or np.any(s < 0):
        raise ValueError(f"size: a {kind} takes {n} finite numbers >= 0, got {s.tolist()}")
    return s


def hull_vertices(points: np.ndarray) -> np.ndarray:
    """(H, 3) the vertices of the convex hull of ``points`` (N, 3) [m], each one of the
    points exactly; all the (distinct) points when their hull is flat or degenerate (fewer
    than 4 points, coplanar, collinear): their hull is the same set."""
    from scipy.spatial import ConvexHull, QhullError

    pts = np.unique(np.asarray(points, np.float64).reshape(-1, 3), axis=0)
    if len(pts) < 4:
        return pts
    try:
        return pts[np.sort(ConvexHull(pts).vertices)]
    except (QhullError, ValueError):
        return pts


def _ellipsoid_axes(g: Any) -> np.ndarray | None:
    """The semi-axes (3,) [m] of an MJCF ellipsoid geom (the MJCF importer stores it as an
    in-memory icosphere scaled by them, ``mesh_uri`` ``"ellipsoid [a, b, c]"``), else None."""
    uri = _get(g, "mesh_uri")
    if _get(g, "mesh") is None or not isinstance(uri, str) or not uri.startswith("ellipsoid ["):
        return None
    try:
        axes = np.array([float(x) for x in uri[len("ellipsoid ["):].rstrip("]").split(",")])
    except ValueError:
        return None
    return axes if axes.shape == (3,) and np.all(axes > 0) else None


def _grown_ellipsoid(vertices: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(V, 3) the vertices of a polytope inscribed in the ellipsoid of semi-axes ``axes``
    (centred at 0) scaled about 0 until their hull holds the ellipsoid: by 1 / the inradius
    of the hull of the vertices mapped onto the unit sphere (a linear map keeps what holds
    what)."""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(vertices / axes)
    inradius = float(np.min(-hull.equations[:, 3]))   # unit normals, 0 inside
    if not inradius > 0:
        raise ValueError("mesh: an ellipsoid's polytope does not hold its centre")
    return vertices[np.sort(hull.vertices)] / inradius


def geometry_piece(kind: str, size: Any = None, origin: Any = None, mesh: Any = None,
                   scale: Any = None) -> tuple[np.ndarray, float]:
    """The piece of one collision geometry in its link's frame (module docstring):
    (vertices (V, 3) [m], radius [m]). ``kind``: ``mesh | box | sphere | capsule |
    cylinder``; ``size``: box (x, y, z) full edges, sphere (r,), capsule and cylinder
    (r, length) along z [m]; ``origin`` (4, 4) pose in the link; ``mesh``: a file or a
    ``trimesh.Trimesh`` in the geometry frame, scaled by ``scale`` (a number or (3,))."""
    if kind == "mesh":
        from jwarp.importers.spheres import _geometry_mesh

        m = _geometry_mesh(kind, size, mesh, scale)
        v = hull_vertices(np.asarray(m.vertices, np.float64))
        return _posed(v, origin), 0.0
    if kind == "box":
        h = _size(size, 3, kind) / 2.0
        corners = np.array([[x, y, z] for x in (-h[0], h[0]) for y in (-h[1], h[1])
                            for z in (-h[2], h[2])])
        return _posed(corners, origin), 0.0
    if kind == "sphere":
        r = _size(size, 1, kind)
        return _posed(np.zeros((1, 3)), origin), float(r[0])
    if kind == "capsule":
        r, length = _size(size, 2, kind)
        ends = np.array([[0.0, 0.0, -length / 2.0], [0.0, 0.0, length / 2.0]])
        return _posed(ends, origin), float(r)
    if kind == "cylinder":
        r, length = _size(size, 2, kind)
        n = CYLINDER_SIDES
        a = 2.0 * np.pi * np.arange(n) / n
        rc = r / math.cos(math.pi / n)           # the polygon's edges touch the circle
        ring = np.stack([rc * np.cos(a), rc * np.sin(a)], axis=1)
        v = np.concatenate([np.column_stack([ring, np.full(n, z)])
                            for z in (-length / 2.0, length / 2.0)])
        return _posed(v, origin), 0.0
    raise ValueError(f"kind: unknown geometry '{kind}', expected one of mesh, box, sphere, "
                     f"capsule, cylinder")


def _piece_of(g: Any) -> tuple[np.ndarray, float, str]:
    """The piece of one importer geometry (``CollisionGeometry`` or a mapping) and what it
    is (``"box"``, ``"mesh hull"``, ...)."""
    kind = _get(g, "kind")
    if kind != "mesh":
        return (*geometry_piece(kind, _get(g, "size"), _get(g, "origin")), str(kind))
    mesh = _get(g, "mesh")
    if mesh is None:   # the file (ValueError naming the link when it is missing)
        mesh = g.mesh_file() if hasattr(g, "mesh_file") else (
            _get(g, "mesh_path") or _get(g, "filename") or _get(g, "path"))
    axes = _ellipsoid_axes(g)
    if axes is not None:
        from jwarp.importers.spheres import _geometry_mesh

        m = _geometry_mesh("mesh", None, mesh, _get(g, "scale"))
        v = _grown_ellipsoid(np.asarray(m.vertices, np.float64), axes)
        return _posed(v, _get(g, "origin")), 0.0, "ellipsoid (grown polytope)"
    return (*geometry_piece("mesh", None, _get(g, "origin"), mesh, _get(g, "scale")),
            "mesh hull")


def pieces_from_geometries(model: RobotModel, geometries: Sequence[Any]) -> CollisionPieces:
    """One :class:`~jwarp.model.ConvexPiece` per collision geometry (module docstring), in
    the frame of its link (``model.frame_index(link)``, as the sphere fit places its
    spheres), ``source`` naming the link, the geometry's number among the link's (from 1)
    and its kind; ``sphere_count``/``sphere_digest`` of ``model``'s spheres.
    ``geometries``: the importer's ``CollisionGeometry`` list (``UrdfRobot.geometries``)
    or mappings with ``link``, ``kind``, ``size``, ``origin``, ``mesh``/``mesh_path``,
    ``scale``. ValueError naming the geometry (index, link) that cannot be made."""
    pieces = []
    seen: dict[str, int] = {}
    for i, g in enumerate(geometries):
        link = _get(g, "link")
        seen[link] = seen.get(link, 0) + 1
        try:
            frame = model.frame_index(link, "link")
            vertices, radius, what = _piece_of(g)
        except (ValueError, TypeError) as e:
            raise type(e)(f"geometries[{i}] (link '{link}'): {e}") from e
        name = _get(g, "name")
        source = f"{link} <collision> {seen[link]} {what}" + (f" '{name}'" if name else "")
        pieces.append(ConvexPiece(frame=frame, vertices=vertices, radius=radius,
                                  source=source))
    return CollisionPieces(pieces=pieces, sphere_count=len(model.spheres),
                           sphere_digest=sphere_digest(model.spheres), method=METHOD)
