"""Scene kinds as objects (jr.Brink, jr.Ramp, jr.Asymmetric) for jr.snap_dynamics: the same run
as the strings with keywords, and contradictions refused by name."""

import pytest

import jaxrod as jr


@pytest.fixture(scope="module")
def scene():
    return jr.make_scene(60, 0.5, n=16)


@pytest.mark.slow  # 9 s (two runs); CI checks that contradicting keywords are refused
def test_brink_object_is_the_string(scene):
    kw = dict(solver=jr.Rattle(courant=0.3), t1=2.0)
    # the object with a keyword that agrees with it: accepted, the same run
    s1, a = jr.snap_dynamics(scene, "up", kind=jr.Brink(nudge=0.02), nudge=0.02, **kw)
    s2, b = jr.snap_dynamics(scene, "up", kind="brink", nudge=0.02, **kw)
    assert float(a.v_s) == float(b.v_s) and int(a.num_steps) == int(b.num_steps)
    assert float(s1.alpha_c) == float(s2.alpha_c)


@pytest.mark.parametrize("kind, kw, name", [
    (jr.Brink(nudge=0.02), dict(nudge=0.05), "nudge"),
    (jr.Ramp(), dict(route="second"), "route"),
    (jr.Asymmetric(rate=1.0), dict(rate=0.3), "rate"),
    (jr.Ramp(rate=0.2), dict(nudge=0.1), "nudge"),
    ("sideways", {}, "kind"),
])
def test_contradictions_are_refused(scene, kind, kw, name):
    with pytest.raises(ValueError, match=name):
        jr.snap_dynamics(scene, "up", kind=kind, **kw)


def test_agreeing_keyword_is_accepted():
    """A keyword equal to the object's own setting is no contradiction: the object's settings
    are the run's (the run itself: `test_brink_object_is_the_string`, nightly)."""
    from jaxrod.dynamics._scenes import _kind_settings

    name, ks = _kind_settings(jr.Brink(nudge=0.02), dict(nudge=0.02, past=1e-3, rate=0.5, route="first"))
    assert name == "brink" and ks["nudge"] == 0.02 and ks["route"] == "first"
    name, ks = _kind_settings(jr.Ramp(rate=0.2), dict(rate=0.2, nudge=jr.dynamics.NUDGE))
    assert name == "ramp" and ks["rate"] == 0.2
