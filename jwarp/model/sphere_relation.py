"""How a robot's collision spheres relate to the meshes they model (``RobotModel.
sphere_relation``, JSON key ``"sphere_relation"``; docs/robot_schema.md, docs/spheres.md).

* ``"contained"``: every point of every collision mesh of a link lies inside the union of
  that link's spheres, up to ``bound`` [m] (0: certified by
  :func:`jwarp.importers.spheres.contain_fit`, a point set of covering radius ``gap`` held
  ``gap`` deep); a path whose spheres are free is free for the meshes.
* ``"approximate"``: mesh points may lie outside the spheres, at most ``poke_out[link]``
  [m] (the certified bound of :func:`jwarp.importers.spheres.containment_bound`), e.g. a
  fit under a ``max_spheres`` budget or the one-sided-error fit
  (``SpherizeOptions(contain=False)``). The planner and IK treat it as extra margin per
  link: :func:`inflated` grows each sphere of a link by that link's poke-out, which makes
  the grown spheres contain the meshes (``PlanOptions.mesh_margin`` /
  ``IKOptions.mesh_margin``, on by default).
* no relation (``None``: a hand-written robot, or a file written before the field
  existed): unknown; nothing is added (:func:`relation_text` says so).

``protrusion[link]`` [m] is how far the link's spheres reach past its surface (the price
of containment: free configurations within that distance of an object are refused).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from jwarp.model import RobotModel

__all__ = ["SphereRelation", "RELATION_KINDS", "relation_from_dict", "relation_to_dict",
           "inflated", "relation_text", "relation_after_edit"]

#: the kinds of :class:`SphereRelation`
RELATION_KINDS = ("contained", "approximate")


@dataclass
class SphereRelation:
    """How the spheres of a robot relate to its collision meshes (module docstring).

    kind: ``"contained"`` or ``"approximate"``.
    bound: ``"contained"``: the largest distance [m] a mesh point may lie outside its
        link's spheres (0: certified); ``"approximate"``: the largest ``poke_out``.
    poke_out: {link (frame) name: the largest distance [m] a point of that link's meshes
        may lie outside its spheres}; links left out: 0 for ``"contained"``, ``bound``
        for ``"approximate"``.
    protrusion: {link name: how far [m] that link's spheres reach past its surface}.
    gap: covering radius [m] of the certificate's point set.
    method: how the figures were found (one line).
    inflated: True when the spheres were already grown by the poke-out
        (:func:`inflated`): then ``kind`` is ``"contained"``.
    sphere_margin: None, or per sphere of the robot (its ``spheres`` order) the radius
        growth [m] that makes the spheres contain the meshes (where it is known: spheres
        shrunk after a contained fit, or the growth a certificate found); :func:`inflated`
        uses it instead of the link's poke-out.
    """

    kind: str
    bound: float = 0.0
    poke_out: dict[str, float] = field(default_factory=dict)
    protrusion: dict[str, float] = field(default_factory=dict)
    gap: float = 0.0
    method: str = ""
    inflated: bool = False
    sphere_margin: list[float] | None = None

    def __post_init__(self) -> None:
        if self.kind not in RELATION_KINDS:
            raise ValueError(f"sphere_relation.kind: expected one of {list(RELATION_KINDS)}, "
                             f"got {self.kind!r}")
        self.bound = _distance(self.bound, "sphere_relation.bound")
        self.gap = _distance(self.gap, "sphere_relation.gap")
        for key in ("poke_out", "protrusion"):
            d = getattr(self, key)
            if not isinstance(d, dict):
                raise TypeError(f"sphere_relation.{key}: expected an object {{link: metres}}, "
                                f"got {type(d).__name__}")
            setattr(self, key, {str(k): _distance(v, f"sphere_relation.{key}.{k}",
                                                  signed=key == "protrusion")
                                for k, v in d.items()})
        if not isinstance(self.method, str):
            raise TypeError(f"sphere_relation.method: expected a string, got "
                            f"{type(self.method).__name__}")
        if self.sphere_margin is not None:
            if not isinstance(self.sphere_margin, (list, tuple)):
                raise TypeError(f"sphere_relation.sphere_margin: expected a list of metres, "
                                f"got {type(self.sphere_margin).__name__}")
            self.sphere_margin = [_distance(v, f"sphere_relation.sphere_margin[{i}]")
                                  for i, v in enumerate(self.sphere_margin)]
        if not isinstance(self.inflated, bool):
            raise TypeError(f"sphere_relation.inflated: expected true or false, got "
                            f"{self.inflated!r}")

    def link_poke_out(self, link: str) -> float:
        """The poke-out [m] of ``link`` (module docstring; links left out: 0 when
        contained, else ``bound``)."""
        return float(self.poke_out.get(link, self.bound))


def _distance(v: Any, where: str, signed: bool = False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) and not hasattr(v, "__float__"):
        raise TypeError(f"{where}: expected a number [m], got {type(v).__name__}")
    x = float(v)
    if not math.isfinite(x) or (x < 0 and not signed):
        raise ValueError(f"{where}: expected a finite distance{'' if signed else ' >= 0'} "
                         f"[m], got {v!r}")
    return x


def relation_to_dict(r: SphereRelation) -> dict[str, Any]:
    """The JSON object of ``r`` (key ``"sphere_relation"`` of the robot document)."""
    out: dict[str, Any] = {"kind": r.kind, "bound": r.bound, "gap": r.gap,
                           "poke_out": dict(r.poke_out), "protrusion": dict(r.protrusion),
                           "method": r.method}
    if r.inflated:
        out["inflated"] = True
    if r.sphere_margin is not None:
        out["sphere_margin"] = list(r.sphere_margin)
    return out


def relation_from_dict(doc: Any) -> SphereRelation | None:
    """A :class:`SphereRelation` from its JSON object (None: None); ValueError/TypeError
    naming the key."""
    if doc is None:
        return None
    if not isinstance(doc, dict):
        raise TypeError(f"sphere_relation: expected an object, got {type(doc).__name__}")
    unknown = set(doc) - {"kind", "bound", "gap", "poke_out", "protrusion", "method",
                          "inflated", "sphere_margin"}
    if unknown:
        raise ValueError(f"sphere_relation: unknown keys {sorted(unknown)}")
    if "kind" not in doc:
        raise ValueError("sphere_relation.kind: missing")
    return SphereRelation(kind=doc["kind"], bound=doc.get("bound", 0.0),
                          poke_out=doc.get("poke_out") or {},
                          protrusion=doc.get("protrusion") or {}, gap=doc.get("gap", 0.0),
                          method=doc.get("method", ""), inflated=doc.get("inflated", False),
                          sphere_margin=doc.get("sphere_margin"))


def inflated(model: RobotModel) -> Any:
    """``model`` (a :class:`~jwarp.model.RobotModel`) with each sphere's radius grown by
    its link's poke-out [m] when its relation is ``"approximate"`` (then every mesh point
    lies inside the grown spheres: the poke-out is a certified bound); the relation of the
    copy is ``"contained"`` with ``inflated`` True, its protrusions grown by the same
    amount. Other models are returned as they are (contained: nothing to add; no
    relation: unknown, nothing added)."""
    rel = getattr(model, "sphere_relation", None)
    if rel is None or rel.kind != "approximate":
        return model
    from dataclasses import replace

    names = [f.name for f in model.frames]
    margin = rel.sphere_margin
    if margin is None or len(margin) != len(model.spheres):
        margin = [rel.link_poke_out(names[s.frame]) for s in model.spheres]
    spheres = [replace(s, position=s.position.copy(), radius=float(s.radius) + float(m))
               for s, m in zip(model.spheres, margin)]
    links = {names[s.frame] for s in model.spheres}
    new = SphereRelation(
        kind="contained", bound=0.0, poke_out={k: 0.0 for k in sorted(links)},
        protrusion={k: rel.protrusion.get(k, 0.0) + rel.link_poke_out(k)
                    for k in sorted(links)},
        gap=rel.gap, inflated=True,
        method=f"approximate spheres grown by their link's poke-out ({rel.method})")
    from jwarp.model.collision_pieces import stamp_pieces

    # the grown spheres cover the same geometry: its collision pieces stand for them too
    return stamp_pieces(model.copy(spheres=spheres, sphere_relation=new))


def relation_text(model: RobotModel) -> str:
    """One line: what the relation of ``model`` promises (for warnings and summaries)."""
    rel = getattr(model, "sphere_relation", None)
    cp = getattr(model, "collision_pieces", None)
    cert = ("; where they cannot prove a motion, the URDF geometry's convex pieces do "
            "(mesh certificate)") if cp is not None and cp.extra_spheres(model) is not None \
        else ""
    if rel is None:
        return ("spheres of unknown relation to the meshes (no 'sphere_relation': no extra "
                "margin added; import again with `jwarp import-urdf` for a contained fit)"
                + cert)
    worst = max(rel.protrusion.values(), default=0.0)
    if rel.kind == "contained":
        return (f"spheres contain the meshes (bound {rel.bound * 1e3:.2f} mm; they reach up "
                f"to {worst * 1e3:.1f} mm past the surface)"
                + (", grown by the measured poke-out" if rel.inflated else "") + cert)
    top = sorted(rel.poke_out.items(), key=lambda kv: -kv[1])[:3]
    return (f"approximate spheres: the meshes poke out of them by up to "
            f"{rel.bound * 1e3:.1f} mm ("
            + ", ".join(f"{k} {v * 1e3:.1f} mm" for k, v in top) + ")" + cert)


def relation_after_edit(rel: SphereRelation | None, names: list[str], old: list,
                        new: list) -> SphereRelation | None:
    """The relation of spheres ``new`` edited from ``old`` (lists of
    :class:`~jwarp.model.Sphere`; ``names``: frame names) whose relation was ``rel``: a
    link whose every old sphere is still there (same frame and centre) with a radius at
    most ``delta`` smaller gets ``delta`` more poke-out (a shrunk sphere uncovers at most
    that much; added spheres only cover more), so a contained model whose spheres were
    tightened becomes approximate with the poke-out it may have now. None (unknown) when
    some link lost or moved a sphere."""
    if rel is None:
        return None
    import numpy as np

    by_link: dict[int, list] = {}
    for s in new:
        by_link.setdefault(int(s.frame), []).append(s)
    shrink: dict[str, float] = {}
    for s in old:
        cands = [t for t in by_link.get(int(s.frame), [])
                 if np.array_equal(np.asarray(t.position), np.asarray(s.position))]
        if not cands:
            return None
        d = float(s.radius) - max(float(t.radius) for t in cands)
        name = names[int(s.frame)]
        shrink[name] = max(shrink.get(name, 0.0), d)
    if all(v <= 0 for v in shrink.values()) and rel.sphere_margin is None:
        return rel
    # per new sphere: the margin of the old sphere it came from, plus how much it shrank
    old_margin = rel.sphere_margin if rel.sphere_margin is not None and \
        len(rel.sphere_margin) == len(old) else None
    margin = []
    for t in new:
        m = 0.0
        for i, s in enumerate(old):
            if int(s.frame) == int(t.frame) and np.array_equal(np.asarray(s.position),
                                                               np.asarray(t.position)):
                base = old_margin[i] if old_margin is not None else \
                    rel.link_poke_out(names[int(s.frame)])
                m = base + max(float(s.radius) - float(t.radius), 0.0)
                break
        margin.append(m)
    if all(v <= 0 for v in shrink.values()):
        return SphereRelation(kind=rel.kind, bound=rel.bound, poke_out=dict(rel.poke_out),
                              protrusion=dict(rel.protrusion), gap=rel.gap,
                              method=rel.method, inflated=rel.inflated, sphere_margin=margin)
    poke = {k: rel.link_poke_out(k) + max(shrink.get(k, 0.0), 0.0)
            for k in sorted(set(rel.poke_out) | set(shrink))}
    prot = {k: v - max(shrink.get(k, 0.0), 0.0) for k, v in rel.protrusion.items()}
    return SphereRelation(kind="approximate", bound=max(poke.values(), default=rel.bound),
                          poke_out=poke, protrusion=prot, gap=rel.gap,
                          method=f"{rel.method}; spheres shrunk afterwards by up to "
                                 f"{max(shrink.values()) * 1e3:.2f} mm (poke-out grown by "
                                 f"as much)", sphere_margin=margin)
