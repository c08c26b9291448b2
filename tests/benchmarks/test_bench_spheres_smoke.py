"""Smoke test of benchmarks/bench_spheres.py: the --quick run (the Panda, few pair samples)
exits 0 and reports both sections; where the Panda meshes are installed, every fitted link
contains its meshes on the benchmark's own fresh check samples (the contained default of
issue 42: no poke-out found), within the default's bounds (<= 200 spheres, hand and fingers
protruding <= CONTAIN_PROTRUSIONS["hand"] x the 1 cm tolerance; the one-sided fit before it:
<= 70 spheres, <= 5 mm)."""

from jwarp.importers.sphere_refine import CONTAIN_PROTRUSIONS


def test_bench_spheres_quick(run_bench):
    stdout, doc = run_bench("bench_spheres.py", "--quick")
    assert stdout.startswith("machine: "), stdout
    assert doc["repeats"] == 2
    pairs = doc["pairs"]
    assert pairs["samples"] == 200 and 0 < pairs["seconds"]["min"] <= pairs["seconds"]["median"]
    assert pairs["adjacent"] > 0 and pairs["kept"] > 0
    robots = {r["robot"]: r for r in doc["robots"]["robots"]}
    panda = robots.get("panda")
    if panda is None or "skipped" in panda:
        return
    assert 0 < panda["spheres"] <= 200, panda["spheres"]
    assert panda["seconds"] > 0 and panda["peak_rss_mb"] < 2048
    links = {r["link"]: r for r in panda["links"]}
    assert sum(r["spheres"] for r in links.values()) == panda["spheres"]
    for r in links.values():
        assert r["spheres"] >= 1 and r["one_sided_error_mm"] <= 1e-6, r
        assert r["excess_cm3"] >= 0
    for name in ("panda_hand", "panda_leftfinger", "panda_rightfinger"):
        assert links[name]["max_protrusion_mm"] <= 10.0 * CONTAIN_PROTRUSIONS["hand"] + 1e-6, \
            links[name]
    assert "| robot |" in stdout
