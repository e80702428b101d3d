"""Verdicts that never mislead (issue 12 part 2): jident_ros/identify/verdict.py through diagnose_window, and the
threshold choice of jident_ros/research/evaluation/verdicts.py.  Every test that publishes nothing also checks that
``on_estimate`` (what the diagnostic node publishes on inertia_estimate) was never called."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def configs():
    from jident_ros.config import load_method_config, load_system_config
    return load_system_config(), load_method_config()


@pytest.fixture(scope="module")
def library(default_library_file):
    """The default configuration's library (conftest: built once per run; ``configs`` are the defaults)."""
    from jident_ros.method.patterns import PatternLibrary
    return PatternLibrary.load(default_library_file)


@pytest.fixture(scope="module")
def windows(configs):
    """0: nominal (a pattern run), 1: 0.957 at eta_k 0.0375."""
    from jident_ros.sim import Case, simulate_grid
    return simulate_grid(configs[0], [Case(1.16, 0.005, 0.025), Case(0.957, 0.005, 0.0375)])


def _diagnose(configs, library, data, *, k2=0.005, r=None, ts=None, entry=48, **kw):
    from test_offline import diagnose_window
    system, method = configs
    published = []
    d = diagnose_window(data, entry, k2, system.load.wheel_radius_m if r is None else r,
                        system.sampling.sample_period_s if ts is None else ts, library=library, system=system,
                        method=method, p=2.0, on_estimate=published.append, **kw)
    return d, published


def _nothing_published(d, published):
    from jident_ros.identify.levels import ERROR
    assert d.inertia_kgm2 is None and published == [], (d.message, published)
    assert d.refused_reason and d.level == ERROR and "internal error" not in d.message, d.message
    assert d.value_dict()["estimate_source"] == "none" and math.isnan(d.value_dict()["inertia_estimate_kgm2"])


def _with(window, name, k, value):
    w = {c: np.array(v, dtype=float) for c, v in window.items()}
    w[name][k] = value
    return w


# ------------------------------------------------------------------------------------------------ bad input

BAD_HEADERS = [  # (field, keyword argument of diagnose_window, value)
    ("sample_period_s", "ts", 0.0),
    ("sample_period_s", "ts", -5e-4),
    ("sample_period_s", "ts", math.nan),
    ("sample_period_s", "ts", math.inf),
    ("wheel_radius_m", "r", 0.0),
    ("wheel_radius_m", "r", -0.1),
    ("wheel_radius_m", "r", math.nan),
    ("backlash_width_m", "k2", 0.0),
    ("backlash_width_m", "k2", -0.005),
    ("backlash_width_m", "k2", math.inf),
    ("entry_index", "entry", 2047),
    ("entry_index", "entry", 3),
    ("entry_index", "entry", 48.5),
]


@pytest.mark.parametrize("field,kw,value", BAD_HEADERS)
def test_a_bad_header_value_is_refused_naming_the_field(configs, library, windows, field, kw, value):
    d, published = _diagnose(configs, library, windows.case(0), **{kw: value})
    _nothing_published(d, published)
    assert d.status == "refused" and d.message.startswith(f"window refused: {field}: "), d.message
    assert d.refused_reason.startswith(f"{field}: ") and "\n" not in d.message


BAD_CONTENT = [  # (channel, sample, value, words the reason must hold)
    ("m_el", 3, 1e300, "exceeds the plausible"),
    ("m_el", 100, -1e6, "exceeds the plausible"),
    ("m_el", 7, math.nan, "non-finite value nan at sample 7"),
    ("a1", 60, math.inf, "non-finite value inf at sample 60"),
    ("alpha1", 5, -math.inf, "non-finite"),
    ("alpha2", 50, math.nan, "non-finite"),
    ("omega1", 0, 1e5, "exceeds the plausible"),
    ("omega2", 2000, -1e4, "exceeds the plausible"),
    ("a2", 10, 1e9, "exceeds the plausible"),
    ("v2", 10, 1e4, "exceeds the plausible"),
    ("t", 48, math.nan, "non-finite"),
]


@pytest.mark.parametrize("channel,k,value,words", BAD_CONTENT)
def test_a_bad_channel_value_is_refused_naming_the_channel(configs, library, windows, channel, k, value, words):
    d, published = _diagnose(configs, library, _with(windows.case(0), channel, k, value))
    _nothing_published(d, published)
    assert d.message.startswith(f"window refused: channel {channel}: ") and words in d.message, d.message


def test_short_and_ragged_windows_are_refused(configs, library, windows):
    w = windows.case(0)
    d, published = _diagnose(configs, library, {c: v[:10] for c, v in w.items()}, entry=4)
    _nothing_published(d, published)
    assert d.message.startswith("window refused: samples: 10 in the window, need >= 2048"), d.message
    ragged = dict(w, m_el=w["m_el"][:-1])
    d, published = _diagnose(configs, library, ragged)
    _nothing_published(d, published)
    assert "channel m_el: 2047 samples" in d.message, d.message
    d, published = _diagnose(configs, library, dict(w, a1=np.zeros((2048, 2))))
    _nothing_published(d, published)
    assert "channel a1: expected one value per sample" in d.message, d.message


@pytest.mark.parametrize("seed", range(6))
def test_random_data_publishes_nothing(configs, library, seed):
    from jident_ros.research.evaluation.verdicts import random_window
    rng = np.random.default_rng(seed)
    data, entry = random_window(rng, seed)
    d, published = _diagnose(configs, library, data, entry=entry)
    _nothing_published(d, published)


# ------------------------------------------------------------------------------------------------ the estimate


def test_j1_outside_the_plausible_band_is_refused_with_the_numbers(configs, library, windows):
    """m_el read with a wrong scale (x3): the gap's J1 is 3.48 kg m^2 -- refused, not published."""
    w = dict(windows.case(0), m_el=windows.case(0)["m_el"] * 3.0)
    d, published = _diagnose(configs, library, w)
    _nothing_published(d, published)
    assert d.status == "refused" and d.gap is not None and abs(d.gap.inertia_kgm2 - 3.48) < 0.01
    assert "J1 = 3.48 kg m^2 is outside the plausible band 0.58..1.74 kg m^2 (0.5..1.5 x the nominal 1.16)" \
        in d.message, d.message
    from jident_ros.identify.verdict import VerdictPolicy
    d, published = _diagnose(configs, library, w, policy=VerdictPolicy(plausible_max_ratio=3.5))
    assert published == [d.inertia_kgm2] and d.status == "between_classes"  # a wider band lets it through


@pytest.mark.parametrize("by_interval", [True, False])
@pytest.mark.parametrize("j1,se,refused", [
    (2.06, 0.28, False),     # 1.51..2.61: reaches into the band (up to 1.74), wider than +-10 %: undetermined
    (0.51, 0.09, False),     # 0.33..0.69: reaches up into the band (from 0.58)
    (2.06, 0.10, True),      # 1.86..2.26: wide (+-9.5 % is not) -- pinned outside the band: refused
    (1.80, 0.03, True),      # 1.74..1.86, +-3.3 %: determined, outside: refused
    (2.76, 0.29, True),      # 2.19..3.33: wide but wholly outside the band: refused
])
def test_j1_outside_the_band_is_a_configuration_error_only_when_its_interval_says_so(
        configs, library, windows, monkeypatch, by_interval, j1, se, refused):
    """BAND_BY_INTERVAL: a J1 outside the plausible band (0.58..1.74) whose 95 % interval is wider than +-10 % and
    reaches into the band cannot tell a wrong K2, radius or torque scale from its own resolution: undetermined, its
    level by the nominal, nothing published -- not ERROR.  Pinned outside (narrow, or wholly outside) it stays refused,
    ERROR; off, every J1 outside the band is refused (stop 42)."""
    import jident_ros.identify.diagnosis as diagnosis
    from jident_ros.identify import verdict
    monkeypatch.setattr(verdict, "BAND_BY_INTERVAL", by_interval)
    monkeypatch.setattr(diagnosis, "estimate_inertia", lambda *a, **kw: _wide_gap(j1, se))
    d, published = _diagnose(configs, library, windows.case(0))
    assert d.inertia_kgm2 is None and published == [] and d.refused_reason, d.message
    if refused or not by_interval:
        assert d.status == "refused" and d.level_name == "ERROR", d.message
        assert "is outside the plausible band 0.58..1.74 kg m^2" in d.message and "a wrong K2" in d.message
    else:
        assert d.status == "ambiguous" and d.level_name in ("OK", "WARN"), d.message
        assert f"undetermined: J1 = {j1:.4g} kg m^2 lies outside the plausible band 0.58..1.74 kg m^2 but its 95 % " \
               "interval" in d.message and "a wrong K2" not in d.message, d.message


@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_a_wrong_backlash_width_publishes_nothing_and_says_so(configs, library, windows, factor):
    d, published = _diagnose(configs, library, windows.case(1), k2=0.005 * factor)
    _nothing_published(d, published)
    assert f"backlash_width_m: the window's K2 = {0.005 * factor:.4g} m disagrees with the re-contact" in d.message
    v = d.value_dict()
    assert v["width_consistent"] is False and abs(v["recontact_width_m"] - 0.005) < 0.0005, v
    # the right K2 is consistent
    d, published = _diagnose(configs, library, windows.case(1))
    assert d.value_dict()["width_consistent"] is True and published == [d.inertia_kgm2]


def _wide_gap(j1, se):
    from jident_ros.identify.gap import GapEstimate
    return GapEstimate(j1, se, (j1 - 1.96 * se, j1 + 1.96 * se), 0.0, 48, 70, "acceleration", "angles")


@pytest.mark.parametrize("j1,se,level,holds", [
    (1.16, 0.02, "OK", "1.131, 1.16, 1.189"),      # the nominal among them: nothing to look at
    (1.09, 0.012, "WARN", "1.073, 1.102"),          # the nominal excluded: look at this drive
])
def test_an_interval_over_two_classes_publishes_j1_without_a_class(configs, library, windows, monkeypatch, j1, se,
                                                                    level, holds):
    """Issue 20: the continuous J1 goes out with its interval (what the data support), no class is named (what
    they do not); the level follows the nominal."""
    import jident_ros.identify.diagnosis as diagnosis
    monkeypatch.setattr(diagnosis, "estimate_inertia", lambda *a, **kw: _wide_gap(j1, se))
    d, published = _diagnose(configs, library, windows.case(0))
    assert d.inertia_kgm2 == j1 and published == [j1] and d.class_kgm2 is None and d.source == "gap"
    assert d.status == "ambiguous" and d.level_name == level, d.message
    lo, hi = j1 - 1.96 * se, j1 + 1.96 * se
    assert d.message.startswith(f"J1 = {j1:.5g} ± {se:.2g} kg m^2 published without a class: ambiguous: 95 % "
                                f"interval {lo:.4g}..{hi:.4g} kg m^2 holds classes {holds}; "), d.message
    assert d.refused_reason is None and d.value_dict()["no_class_reason"].startswith("ambiguous: ")
    assert math.isnan(d.value_dict()["identified_class_kgm2"]) and d.value_dict()["inertia_estimate_kgm2"] == j1


@pytest.mark.parametrize("j1,se,level,holds", [
    (1.16, 0.02, "OK", "1.131, 1.16, 1.189"),
    (1.09, 0.012, "WARN", "1.073, 1.102"),
])
def test_publish_ambiguous_false_publishes_nothing_for_an_interval_over_two_classes(configs, library, windows,
                                                                                     monkeypatch, j1, se, level, holds):
    """publish_ambiguous: false, issue 12's first reading: nothing goes out, the status says why."""
    import jident_ros.identify.diagnosis as diagnosis
    from jident_ros.identify.verdict import VerdictPolicy
    monkeypatch.setattr(diagnosis, "estimate_inertia", lambda *a, **kw: _wide_gap(j1, se))
    d, published = _diagnose(configs, library, windows.case(0), policy=VerdictPolicy(publish_ambiguous=False))
    assert d.inertia_kgm2 is None and published == [] and d.class_kgm2 is None
    assert d.status == "ambiguous" and d.level_name == level, d.message
    lo, hi = j1 - 1.96 * se, j1 + 1.96 * se
    assert d.message.startswith(f"ambiguous: 95 % interval {lo:.4g}..{hi:.4g} kg m^2 holds classes {holds}: "
                                f"no class named, nothing published"), d.message
    assert d.refused_reason.startswith("ambiguous: ")


@pytest.mark.parametrize("j1,se,level", [
    (1.20, 0.07, "OK"),       # ± 11 %, the nominal inside: this window cannot resolve J1, nothing against the drive
    (0.70, 0.04, "WARN"),     # ± 11 %, the nominal 11 standard errors away: the drive has changed, by how much unknown
])
def test_an_interval_wider_than_ten_percent_is_undetermined_not_an_error(configs, library, windows, monkeypatch, j1,
                                                                          se, level):
    """Not a fault of the monitor's configuration (ERROR) but this window's resolution (a low-torque return
    traversal): no J1 published, the level follows the nominal as for an interval over two classes; the trend
    takes it with its standard error (status 'ambiguous': trend_status.refusal_kind)."""
    import jident_ros.identify.diagnosis as diagnosis
    from jident_ros.identify.trend_status import refusal_kind
    monkeypatch.setattr(diagnosis, "estimate_inertia", lambda *a, **kw: _wide_gap(j1, se))
    d, published = _diagnose(configs, library, windows.case(0))
    assert d.inertia_kgm2 is None and published == [] and d.class_kgm2 is None
    assert d.status == "ambiguous" and d.level_name == level, d.message
    assert d.message.startswith("undetermined: 95 % interval ") and "nothing published" in d.message, d.message
    assert refusal_kind(d) is None


@pytest.mark.parametrize("why,level", [
    ("gap too short: 2 samples inside the zone, need >= 3", "OK"),
    ("gap fit undetermined: J1 = 1.2 kg m^2 with standard error 0.4 kg m^2 (> 25%); the window shows no free "
     "acceleration of the motor", "OK"),
    ("a1 fit: gap fit undetermined: J1 = 1.3 kg m^2 with standard error 0.5 kg m^2 (> 25%); the window shows no free "
     "acceleration of the motor; angle fit: gap too short: 5 samples consistent with a free motor, need >= 8", "OK"),
    ("a1 fit: gap fit undetermined: J1 = 1.3 kg m^2 with standard error 0.5 kg m^2 (> 25%); angle fit: gap fit gave "
     "a non-physical 1/J1 from alpha1", "ERROR"),
    ("gap fit gave a non-physical J1 = -0.3", "ERROR"),
    ("the a1 fit (gap_only: J1 = 1.431 ± 0.016 kg m^2) and the angle fit (J1 = 1.151 ± 0.018 kg m^2) disagree by "
     "11.6 standard errors (> 3): friction, a wrong gap interval or a lagging signal", "ERROR"),
])
def test_a_gap_that_cannot_resolve_j1_is_not_an_error(configs, library, windows, monkeypatch, why, level):
    """A gap too short, or a fit whose standard error is above 25 %, says only that this window cannot resolve J1
    (a low-torque return traversal): OK, nothing published. A non-physical or inconsistent fit says something is
    wrong with the sensors or the configuration: ERROR."""
    import jident_ros.identify.diagnosis as diagnosis
    from jident_ros.identify.gap import NoGapError

    def fail(*a, **kw):
        raise NoGapError(why)
    from jident_ros.identify.verdict import VerdictPolicy
    monkeypatch.setattr(diagnosis, "estimate_inertia", fail)
    # the image method never answers alone (margin 0): its untrusted class is information, not a problem
    d, published = _diagnose(configs, library, windows.case(0), policy=VerdictPolicy(image_min_margin=0.0))
    assert d.inertia_kgm2 is None and published == [] and d.status == "undiagnosed"
    assert d.level_name == level, d.message
    assert d.message.startswith("no J1 from this window: gap: " if level == "OK" else "window could not be diagnosed"), \
        d.message


def test_a_healthy_nominal_window_is_ok(configs, library, windows):
    from jident_ros.sim import Case, simulate_grid
    ws = simulate_grid(configs[0], [Case(1.16, 0.005, 0.0375), Case(1.16, 0.0025, 0.05)])  # off the pattern runs
    for i in range(2):
        d, published = _diagnose(configs, library, ws.case(i), k2=ws.cases[i].backlash_width_m)
        assert d.level_name == "OK" and d.status == "nominal" and published == [d.inertia_kgm2], d.message


# ------------------------------------------------------------------------------------------------ policy


def test_policy_defaults_are_the_diagnostic_nodes():
    from dataclasses import fields

    from jident_ros.identify.verdict import VerdictPolicy
    from jident_ros.parameters import DIAGNOSTIC
    for f in fields(VerdictPolicy):
        assert DIAGNOSTIC[f.name] == getattr(VerdictPolicy(), f.name), f.name


@pytest.mark.parametrize("name,value,what", [
    ("image_min_margin", 0.5, "0 (never) or a margin >= 1"),
    ("plausible_min_ratio", 1.2, "a number in (0, 1)"),
    ("plausible_max_ratio", 0.9, "a number > 1"),
    ("library_width_tolerance", 0.0, "a number > 0"),
    ("max_speed_factor", math.nan, "a finite number"),
    ("publish_ambiguous", 1.0, "true or false"),
])
def test_bad_policy_values_name_the_field(name, value, what):
    from jident_ros.identify.verdict import VerdictPolicy
    with pytest.raises(ValueError) as exc:
        VerdictPolicy(**{name: value}).check()
    assert str(exc.value) == f"{name}: must be {what}, got {value!r}"


# ------------------------------------------------------------------------------------------------ threshold


def test_threshold_is_the_smallest_margin_meeting_the_error_target():
    from jident_ros.research.evaluation.verdicts import choose_image_threshold
    # 200 windows, margins 1.01 .. 3.0; wrong below 2.0 every other window, above 2.0 one in 150
    m = np.linspace(1.01, 3.0, 200)
    ok = np.ones(200, bool)
    ok[(m < 2.0) & (np.arange(200) % 2 == 0)] = False
    ok[199] = False   # the largest margin wrong once
    c = choose_image_threshold(m, ok, 0.01, 50)
    sel = m >= c.threshold
    assert c.answered == sel.sum() and c.wrong == (~ok[sel]).sum() <= 0.01 * c.answered and c.answered >= 50
    below = m[m < c.threshold].max()   # the next smaller margin fails the target
    s2 = m >= below
    assert (~ok[s2]).sum() > 0.01 * s2.sum()
    # fewer windows than min_count: no threshold, the image method never publishes alone
    c = choose_image_threshold(m, ok, 0.01, 500)
    assert c.threshold is None and c.parameter_value == 0.0 and c.total == 200
    # always wrong: none
    assert choose_image_threshold(m, np.zeros(200, bool), 0.01, 10).threshold is None
    # ties are taken together; inf margins (pattern runs) never become the threshold
    c = choose_image_threshold([2.0, 2.0, 2.0, math.inf], [True, True, False, True], 0.5, 1)
    assert c.threshold == 2.0 and c.answered == 4 and c.wrong == 1
    with pytest.raises(ValueError, match="margins and correct"):
        choose_image_threshold([1.0, 2.0], [True])


@pytest.mark.slow
def test_the_default_image_min_margin_is_what_the_command_gives(configs, library):
    """The default of image_min_margin comes from `python -m jident_ros.research.evaluation.verdicts threshold`
    (rerun it after changing the drive and put its value in parameters.py, nodes.yaml, VerdictPolicy)."""
    from jident_ros.identify.verdict import VerdictPolicy
    from jident_ros.research.evaluation.verdicts import choose_image_threshold, image_evaluation_set
    s = image_evaluation_set(*configs, library)
    assert choose_image_threshold(s.margins, s.correct).parameter_value == pytest.approx(
        VerdictPolicy().image_min_margin, rel=1e-6)


# ------------------------------------------------------------------------------------------------ reverse rotation


def test_a_reverse_window_is_mirrored_before_the_image_method(configs, library, windows):
    """A reverse window (every channel but t negated: the model is odd) gives the forward window's image class and
    margin, and ``image_rotation`` says it was mirrored; the forward window carries no such key.  Without the mirror
    the image method is not sign-invariant: the margin on the raw reverse window differs (checked here too)."""
    from jident_ros.identify.diagnosis import mirrored
    from jident_ros.method.patterns import identify_window
    system, method = configs
    for i in range(2):
        fwd = windows.case(i)
        rev = mirrored(fwd)
        df, _ = _diagnose(configs, library, fwd)
        dr, _ = _diagnose(configs, library, rev)
        vf, vr = df.value_dict(), dr.value_dict()
        assert "image_rotation" not in vf and vr["image_rotation"] == "reverse (mirrored)", (vf, vr)
        assert vr["image_class_kgm2"] == vf["image_class_kgm2"] and vr["image_margin"] == vf["image_margin"]
        raw = identify_window(rev, 48, 0.005, library, method, 2.0)
        assert raw.fused_margin != pytest.approx(vf["image_margin"], rel=1e-6), "the raw reverse window is no test"


def test_image_min_margin_applies_only_to_the_variant_it_was_chosen_for():
    """The margin threshold was chosen on the paper-faithful distances: a sensor_matched answer with the same margin
    is outside the trusted domain (information only, never published alone), with the reason."""
    from jident_ros.identify.verdict import VerdictPolicy, image_domain
    policy = VerdictPolicy()
    args = (5.0, 0.005, 0.005, 5e-4, 5e-4, policy)
    assert image_domain(*args) == (True, "")
    inside, reason = image_domain(*args, variant="sensor_matched")
    assert not inside and "'sensor_matched'" in reason and "image_min_margin" in reason


@pytest.mark.parametrize("terms,names", [
    # the vector drive's heavy load reversal: 2 N m of gap torque against the declared offset band
    ((("statistical", 0.007), ("torque_offset", 0.143), ("torque_lag", 0.027)),
     ("an unknown constant torque in the gap", "± 24.1 %", "bounded by torque_offset_rel_base")),
    # a short gap on a coarse encoder: only the data narrow it
    ((("statistical", 0.143), ("torque_offset", 0.007), ("torque_accuracy", 0.02)),
     ("the samples themselves", "± 24.1 %", "only more data narrow it")),
    ((("torque_lag", 0.09), ("change_points", 0.02)), ("the torque estimate's lag", "bounded by torque_lag_max_s")),
])
def test_an_undetermined_refusal_names_its_largest_part_and_the_key_that_bounds_it(terms, names):
    """A user whose drive gives 'undetermined' learns what widens the interval: a declared band (which a better
    declaration may narrow) or the data; the part's share is of the 95 % half-width (its share of se)."""
    from dataclasses import replace

    from jident_ros.identify.verdict import VerdictPolicy, decide_gap
    se = 0.146   # the interval ± 1.96 x 0.146 / 1.165 = ± 24.6 %; a part of 0.143: ± 24.6 x 0.143 / 0.146 = ± 24.1 %
    base = _wide_gap(1.165, se)
    gap = replace(base, std_error_terms=terms)
    d = decide_gap(gap, (1.073, 1.16, 1.247), 1.16, VerdictPolicy(), None, 0.005)
    assert d.status == "ambiguous" and not d.publish
    tail = d.reason.split("; the largest part: ", 1)[1]
    for n in names:
        assert n in tail, d.reason
    # without parts, the message is the plain one
    assert "largest part" not in decide_gap(base, (1.073, 1.16, 1.247), 1.16, VerdictPolicy(), None, 0.005).reason
