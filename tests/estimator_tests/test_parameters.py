"""Parameter keys: the one instance rule (:func:`estimator.parameters.instance_of`), the one key
resolver (:meth:`estimator.parameters.ParameterSet.key_of`) and the instances
:func:`estimator.problem.expand_parameters` expands families over."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.parameters import SCOPES, ParameterSet, ParameterSpec, instance_of, make_key
from estimator.problem import ChannelSpec, ManeuverData, expand_parameters


def _maneuver(id_: str, aircraft: str = "PV1", configuration: str = "clean") -> ManeuverData:
    t_s = np.arange(5) * 0.1
    return ManeuverData(id=id_, t_s=t_s, accel_imu_mps2=np.zeros((5, 3)), omega_rps=np.zeros((5, 3)),
                        measurements={"q_rad": np.zeros(5)}, r_cg_body_m=np.zeros(3),
                        aircraft=aircraft, configuration=configuration)


def _channel(recorder: str) -> ChannelSpec:
    return ChannelSpec(name=f"q_{recorder}", column="q_rad", model="q + b_q", recorder=recorder)


#: one family per scope, and a global table and a per-aircraft table (elements)
SPECS = [
    ParameterSpec("tau", "s", 0.01, scope="global"),
    ParameterSpec("b_l", "rad", scope="aircraft"),
    ParameterSpec("k_c", "1", 1.0, scope="configuration"),
    ParameterSpec("tau_rec", "s", scope="recorder"),
    ParameterSpec("u0", "m/s", 150.0, scope="maneuver"),
    ParameterSpec("f1", "rad", (0.0, 0.1, 0.2), breakpoints=(-0.1, 0.0, 0.1), kind="table"),
    ParameterSpec("f2", "rad", 0.0, scope="aircraft", breakpoints=(0.0, 1.0), kind="table"),
]
M1 = _maneuver("m0002", aircraft="PV1", configuration="clean")
M2 = _maneuver("m0001", aircraft="PT1", configuration="gear")
DRU, ADC = _channel("dru"), _channel("adc")


@pytest.fixture(scope="module")
def ps() -> ParameterSet:
    return expand_parameters(SPECS, [M1, M2], [DRU, ADC])


@pytest.mark.parametrize(("scope", "maneuver", "channel", "instance"), [
    ("global", M1, None, ""),
    ("global", M1, DRU, ""),
    ("aircraft", M1, None, "PV1"),
    ("aircraft", M2, DRU, "PT1"),
    ("configuration", M1, None, "clean"),
    ("configuration", M2, None, "gear"),
    ("maneuver", M1, None, "m0002"),
    ("maneuver", M2, ADC, "m0001"),
    ("recorder", M1, DRU, "dru"),
    ("recorder", M1, ADC, "adc"),
    ("recorder", M1, None, ""),  # no channel, no recorder
])
def test_instance_of_each_scope(scope, maneuver, channel, instance):
    assert instance_of(scope, maneuver, channel) == instance


def test_every_scope_is_covered():
    # a new scope must get a rule in instance_of (and a case above)
    assert {s: instance_of(s, M1, DRU) for s in SCOPES} == {
        "global": "", "aircraft": "PV1", "configuration": "clean", "recorder": "dru", "maneuver": "m0002"}


@pytest.mark.parametrize(("name", "maneuver", "channel", "key"), [
    ("tau", M1, None, "tau"),
    ("b_l", M1, None, "b_l[PV1]"),
    ("b_l", M2, DRU, "b_l[PT1]"),
    ("k_c", M1, None, "k_c[clean]"),
    ("k_c", M2, None, "k_c[gear]"),
    ("tau_rec", M1, DRU, "tau_rec[dru]"),
    ("tau_rec", M2, ADC, "tau_rec[adc]"),
    ("u0", M1, None, "u0[m0002]"),
    ("u0", M2, DRU, "u0[m0001]"),
])
def test_key_of_each_scope_names_a_parameter_of_the_set(ps, name, maneuver, channel, key):
    assert ps.key_of(name, maneuver, channel) == key
    p = ps[key]
    assert (p.name, p.instance, p.element) == (name, instance_of(p.scope, maneuver, channel), None)


def test_key_of_a_table_element(ps):
    assert ps.key_of("f1", M1, element=2) == "f1[2]"
    assert ps["f1[2]"].value == pytest.approx(0.2)
    assert ps.key_of("f2", M2, DRU, element=1) == "f2[PT1][1]"
    p = ps["f2[PT1][1]"]
    assert (p.name, p.instance, p.element) == ("f2", "PT1", 1)


def test_key_of_an_unknown_family_names_the_declared_ones(ps):
    with pytest.raises(KeyError, match=r"no parameter family 'b_x'; declared: \['b_l', 'f1', 'f2', "
                                       r"'k_c', 'tau', 'tau_rec', 'u0'\]"):
        ps.key_of("b_x", M1)


def test_expand_parameters_instances_sorted_but_maneuvers_in_their_order(ps):
    assert ps.keys == [
        "tau", "b_l[PT1]", "b_l[PV1]", "k_c[clean]", "k_c[gear]", "tau_rec[adc]", "tau_rec[dru]",
        "u0[m0002]", "u0[m0001]", "f1[0]", "f1[1]", "f1[2]",
        "f2[PT1][0]", "f2[PT1][1]", "f2[PV1][0]", "f2[PV1][1]",
    ]


# ---------------------------------------------------------------------------- properties
# No function parses a key back (estimator/ looks keys up, never splits them); the properties are
# that make_key is one-to-one and that every key the resolver gives is the key of the parameter
# it stands for.

_ids = st.text("abcXYZ019_-.", min_size=1, max_size=6)  # aircraft, configuration, recorder, maneuver ids
_names = st.from_regex(r"[a-z][a-z0-9_]{0,5}", fullmatch=True)  # family names are identifiers


@pytest.mark.slow
@given(data=st.data(), names=st.tuples(_names, _names), tables=st.tuples(st.booleans(), st.booleans()))
@settings(max_examples=300, deadline=None)
def test_make_key_is_one_to_one(data, names, tables):
    # a family is a table or not for all its instances ("f[1]" is element 1 of a global table f or
    # instance "1" of a scalar f, never both: a family has one shape)
    tables = (tables[0], tables[0]) if names[0] == names[1] else tables
    a, b = ((n, data.draw(st.just("") | _ids), data.draw(st.integers(0, 20)) if t else None)
            for n, t in zip(names, tables, strict=True))
    assert (make_key(*a) == make_key(*b)) == (a == b)


@given(maneuvers=st.lists(st.tuples(_ids, _ids, _ids), min_size=1, max_size=4,
                          unique_by=lambda m: m[0]),
       recorders=st.lists(_ids, min_size=1, max_size=3, unique=True),
       element=st.integers(0, 1))
@settings(max_examples=100, deadline=None)
def test_the_resolver_gives_the_key_of_the_parameter_it_stands_for(maneuvers, recorders, element):
    mans = [_maneuver(i, aircraft=a, configuration=c) for i, a, c in maneuvers]
    chans = [_channel(r) for r in recorders]
    ps = expand_parameters(SPECS, mans, chans)
    for p in ps:
        assert p.key == make_key(p.name, p.instance, p.element)
    for m in mans:
        for ch in chans:
            for spec in SPECS:
                el = None if spec.breakpoints is None else element
                p = ps[ps.key_of(spec.name, m, ch, el)]
                assert (p.name, p.instance, p.element) == (spec.name, instance_of(spec.scope, m, ch), el)
    # one scalar per instance the data use, and no other
    n_used = {s: len({instance_of(s, m, ch) for m in mans for ch in chans}) for s in SCOPES}
    assert len(ps) == sum(n_used[s.scope] * s.size for s in SPECS)
