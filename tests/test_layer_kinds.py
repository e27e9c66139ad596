"""A layer kind added from outside the package, in this module alone: registered, validated from
its declared fields, planned, solved and walked, with no change to layersim.

The toy kind is a grey absorbing film: a field ``transmittance`` (per channel, in (0, 1]), the
normal-incidence transmittance of a non-scattering slab of optical thickness ``tau = -ln T``. Over
a Lambertian base of albedo ``a`` the stack reflects, in closed form (Beer-Lambert both ways,
no interface),

    R(mu_i) = a exp(-tau / mu_i) 2 E_3(tau),

with ``E_3`` the exponential integral of order 3 (``2 E_3(tau) = 2 int_0^1 exp(-tau/mu) mu dmu``).
"""
import math
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.special import expn

import layersim
import layersim.montecarlo as mc
from layersim.errors import SceneError
from layersim.ingredients.medium import medium_operator
from layersim.layers import KINDS, Field, Layer, LayerKind, LayerPlan, kind_named, register
from layersim.layers.fields import real


@dataclass(frozen=True)
class GreyFilm(Layer):
    kind = "grey_film"
    transmittance: float = 1.0

    @property
    def tau(self) -> float:
        return -math.log(self.transmittance)


class GreyFilmKind(LayerKind):
    name = "grey_film"
    record = GreyFilm
    walk_role = "slab"
    fields = (Field("transmittance", "normal-incidence transmittance",
                    parse=real(lo=0.0, hi=1.0, lo_open=True), required=True, per_channel=True,
                    fit=True),)

    def build(self, ctx, values, raw, defaults):
        return [GreyFilm(t) for t in values["transmittance"]]

    def describe(self, per_channel):
        return "grey film T=" + self.values(per_channel, lambda x: f"{x.transmittance:g}")

    def survey(self, scene, i, survey):
        survey.layers.append(LayerPlan(i, self.name, "Beer-Lambert film", "unscattered beam"))

    def operator(self, job):
        return medium_operator(job.grid, job.plan.md, 0.0, 0.0, job.layer.tau, job.eta_above)

    def walk_slab(self, layer):
        return (layer.tau, 0.0, 0.0)


@pytest.fixture(scope="module")
def grey_film():
    kind = register(GreyFilmKind())
    yield kind
    del KINDS[kind.name]


def scene(t=0.5, albedo=0.8):
    return layersim.Scene.from_dict({"layer": [{"kind": "grey_film", "transmittance": t},
                                               {"kind": "diffuse", "albedo": albedo}]})


def test_the_kind_is_registered_and_validated_from_its_fields(grey_film):
    assert kind_named("grey_film") is grey_film
    assert grey_film.fit_parameters() == ("transmittance",)
    s = scene()
    assert s.layers[0] == GreyFilm(0.5) and "grey film T=0.5" in s.describe()
    rgb = layersim.Scene.from_dict({"layer": [
        {"kind": "grey_film", "transmittance": [0.2, 0.5, 0.9]}, {"kind": "diffuse", "albedo": 0.5}]})
    assert rgb.channels == 3 and rgb.channel(2).layers[0].transmittance == 0.9
    for raw, words in (({"kind": "grey_film", "transmittance": 0.0}, ("field 'transmittance'",
                                                                       "must be > 0")),
                       ({"kind": "grey_film"}, ("field 'transmittance'", "is required")),
                       ({"kind": "grey_film", "transmittance": 0.5, "tint": 1},
                        ("field 'tint'", "allowed: transmittance"))):
        with pytest.raises(SceneError) as err:
            layersim.Scene.from_dict({"layer": [raw, {"kind": "diffuse", "albedo": 0.5}]})
        assert all(w in str(err.value) for w in ("layer 0 (grey_film)",) + words)
    with pytest.raises(SceneError, match="grey_film"):
        layersim.Scene.from_dict({"layer": [{"kind": "grey_flim"}]})


def test_the_kind_is_planned_and_solved_to_the_closed_form(grey_film):
    plan = layersim.make_plan(scene())
    assert "layer 0 (grey_film): Beer-Lambert film" in plan.report()
    bsdf = layersim.solve(scene())
    tau = -math.log(0.5)
    for deg in (0.0, 30.0, 60.0):
        mu = math.cos(math.radians(deg))
        wi = np.array([math.sqrt(1 - mu * mu), 0.0, mu])
        R = float(bsdf.albedo(wi)[0])
        assert R == pytest.approx(0.8 * math.exp(-tau / mu) * 2 * expn(3, tau), rel=2e-3)


def test_the_kind_is_walked_to_the_closed_form(grey_film):
    tau = -math.log(0.5)
    wi = np.array([0.5, 0.0, math.sqrt(0.75)])
    res = mc.simulate(scene(), wi, 200_000, backend="warp-cpu", seed=3)
    exact = 0.8 * math.exp(-tau / wi[2]) * 2 * expn(3, tau)
    assert abs(res.reflectance - exact) < 4 * res.reflectance_stderr
