"""pbrt-v4's layered BSDFs against ``layersim.solve`` of the same stacks (issue 35).

The four parameter sets of ``shared/refdata/pbrt4_layered.json`` (pbrt-v4's
``CoatedConductorBxDF`` / ``CoatedDiffuseBxDF``, built and evaluated outside this project; its
conventions inside) are imported through ``Scene.from_pbrt`` (GGX, pbrt-v4's height-correlated
Smith term) and solved to ``tol = 1e-3``; the Beta-function form in transmission (Heitz 2014,
eq. 100) and the separable Smith term (Mitsuba 3's and this package's default) are solved too,
to show what the term changes. Printed per
set: the directional albedos against pbrt-v4's ``Sample_f`` (in units of the tolerance
max(3 standard errors, 1e-3)), the relative L2 error and median relative error of ``f`` over
the direction pairs against pbrt-v4's ``LayeredBxDF::f`` unmodified (``f``) and with the MIS
fix of pbrt-v4 issue 187 (``f_patched``), the solve time and the time of one ``eval``, beside
pbrt-v4's time per ``Sample_f`` and the noise of its ``f`` values (from the file).

Usage::

    python benchmarks/accuracy/pbrt_v4_layered.py [REFDATA.json] \
        > benchmarks/accuracy/pbrt_v4_layered.txt
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

import layersim
from layersim.bench.report import machine_info

#: Where the shared reference data live: beside the checkout, or the shared folder of the
#: machine the comparison was made on.
CANDIDATES = [Path(__file__).resolve().parents[3] / "shared" / "refdata" / "pbrt4_layered.json",
              Path("/work/shared/refdata/pbrt4_layered.json")]
TOL = 1e-3


def pbrt_text(p: dict) -> str:
    """The pbrt-v4 ``Material`` directive of a parameter set of the reference file."""
    common = (f'"float thickness" {p["thickness"]} "rgb albedo" [{p["albedo"]} {p["albedo"]} '
              f'{p["albedo"]}] "float g" {p["g"]} "bool remaproughness" false '
              f'"integer maxdepth" {p["maxdepth"]} "integer nsamples" {p["nsamples"]}')
    if "reflectance" in p:
        return (f'Material "coateddiffuse" "float roughness" {p["interface_alpha"]} '
                f'"float eta" {p["interface_eta"]} "float reflectance" {p["reflectance"]} '
                + common)
    return (f'Material "coatedconductor" "float interface.roughness" {p["interface_alpha"]} '
            f'"float interface.eta" {p["interface_eta"]} '
            f'"float conductor.roughness" {p["conductor_alpha"]} '
            f'"spectrum conductor.eta" [{p["conductor_eta"]}] '
            f'"spectrum conductor.k" [{p["conductor_k"]}] ' + common)


def compare(key: str, data: dict, shadowing: str) -> list[str]:
    """The report lines of one set solved with ``shadowing``."""
    scene = layersim.Scene.from_pbrt(pbrt_text(data["material_params"]), name=key)
    if shadowing != "height-correlated":
        scene = layersim.Scene.from_dict({"stack": {"shadowing": shadowing},
                                          "layer": _layers(data)})
    t0 = time.perf_counter()
    bsdf = layersim.solve(scene, tol=TOL)
    seconds = time.perf_counter() - t0
    cells = []
    for a in data["albedo_Sample_f_1e7"]:
        got = float(bsdf.albedo(np.array(a["wo"]))[0])
        units = (got - a["albedo"]) / max(3 * a["albedo_stderr"], 1e-3)
        cells.append(f"{a['theta_o_deg']:>2.0f}: {got:.5f} vs {a['albedo']:.5f} "
                     f"({100 * (got / a['albedo'] - 1):+.2f} %, {units:+.2f} tol)")
    lines = [f"{key} {shadowing:<22} n={bsdf.info['n']} md={bsdf.info['md']} "
             f"solve {seconds:.1f} s, eval {_eval_microseconds(bsdf):.2f} us per f value"]
    lines += ["    albedo " + c for c in cells]
    if "pairs" in data:
        wo = np.array([q["wo"] for q in data["pairs"]])
        wi = np.array([q["wi"] for q in data["pairs"]])
        f = bsdf.eval(wi, wo)
        for col in ("f", "f_patched"):
            ref = np.array([q[col] for q in data["pairs"]])
            l2 = np.linalg.norm(f - ref) / np.linalg.norm(ref)
            med = np.median(np.abs(f / ref - 1))
            worst = int(np.argmax(np.abs(f / ref - 1)))
            q = data["pairs"][worst]
            lines.append(f"    {col:<9} over {len(ref)} pairs: relative L2 {100 * l2:.2f} %, "
                         f"median {100 * med:.2f} %, worst {100 * (f[worst] / ref[worst] - 1):+.1f}"
                         f" % at theta_o {q['theta_o_deg']:g}, theta_i {q['theta_i_deg']:g}, "
                         f"phi_i {q['phi_i_deg']:g}")
    return lines


def _eval_microseconds(bsdf, n: int = 100_000) -> float:
    """Time of ``bsdf.eval`` per direction pair (us), over ``n`` random pairs above."""
    rng = np.random.default_rng(0)
    w = rng.normal(size=(2, n, 3))
    w[..., 2] = np.abs(w[..., 2])
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    t0 = time.perf_counter()
    bsdf.eval(w[0], w[1])
    return 1e6 * (time.perf_counter() - t0) / n


def pbrt_costs(data: dict) -> str:
    """pbrt-v4's side from the reference file: time per Sample_f call (seconds / N) and the
    median relative standard error of its f values (K evaluations of nSamples walks each)."""
    per = [a["seconds"] / a["N"] * 1e6 for a in data["albedo_Sample_f_1e7"]]
    text = f"    pbrt-v4: Sample_f {min(per):.2f}-{max(per):.2f} us per sample"
    if "pairs" in data:
        rel = [q["f_patched_stderr"] / q["f_patched"] for q in data["pairs"]]
        text += (f"; f_patched median relative standard error {100 * np.median(rel):.2f} % "
                 f"(nSamples = {data['material_params']['nsamples']:g} walks per evaluation)")
    return text


def _layers(data):
    from layersim.pbrtimport import pbrt_to_dict
    return pbrt_to_dict(pbrt_text(data["material_params"]))[0]["layer"]


def main(argv: list[str]) -> int:
    path = Path(argv[1]) if len(argv) > 1 else next((p for p in CANDIDATES if p.exists()),
                                                    CANDIDATES[0])
    ref = json.loads(path.read_text())
    m = machine_info("python benchmarks/accuracy/pbrt_v4_layered.py")
    print(f"# {m['cpu']} ({m['cores']} cores), commit {m['layersim_commit']}, {m['date']}")
    print(f"# reference: {path.name}: {ref['what'][:120]}...")
    print(f"# layersim.solve(scene, tol={TOL:g}); tol = max(3 standard errors, 1e-3)")
    for key, data in ref["sets"].items():
        print(pbrt_costs(data))
        for shadowing in ("height-correlated", "height-correlated-beta", "separable"):
            print("\n".join(compare(key, data, shadowing)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
