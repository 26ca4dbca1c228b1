# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The paper-protocol evaluation on small synthetic libraries (fast)."""

from __future__ import annotations

import numpy as np
import pytest

from tofmat import sim
from tofmat.sim import evaluate as ev

STAGE = np.arange(600.0, 1250.0 + 1e-9, 10.0)


def renderer(materials: list[dict[str, object]], noise: bool = True, harmonics: bool = True) -> sim.Renderer:
    dev = sim.DeviceProfile.ideal_kinect2().to_dict()
    for k, f in enumerate(dev["frequencies"]):
        if harmonics:
            f["harmonics"] = [{"h": h, "amplitude": 0.03, "phase_rad": 0.7 * h + k} for h in range(2, 8)]
    if noise:
        dev["noise"] = {"read_noise": 3.0, "shot_gain": 0.03, "ambient": 100.0}
    lib = sim.MaterialLibrary.from_dict({"name": "t", "version": 1, "materials": materials})
    return sim.Renderer(sim.DeviceProfile.from_dict(dev), lib)


def mat(name: str, tau_ps: float, b: float) -> dict[str, object]:
    return {"name": name, "kind": "exponential", "albedo": 0.7, "subsurface": b, "tau_ps": tau_ps}


def test_depth_feature_is_eq11_and_vanishes_for_an_opaque_target() -> None:
    # Eq. (11): d(f, base) - d(f, j) + (stage_j - stage_base). An opaque target on an
    # ideal device measures range (= stage / cos of the ray angle, ~ stage at the
    # centre) scaled by 300/299.79, so the feature is ~0 up to that 0.07 % scale
    # (and the ROI's ray angles: < 4e-4 of the stage offset). The 11-bit code's
    # companding quantises bright near samples in steps of 16-32 counts, a phase
    # error of up to ~2e-3 rad (0.4 mm at 120 MHz) before the ROI averages it.
    r = renderer([{"name": "wall", "kind": "opaque", "albedo": 0.7}], noise=False, harmonics=False)
    c = ev.capture(r, "wall", 0.0, STAGE, seed=1)
    v = ev.feature_depth(c, 2, len(STAGE) // 2)
    assert v.shape == (1, len(STAGE))
    scale = 300.0 / 299.792458 - 1.0
    expected = -(STAGE - STAGE[len(STAGE) // 2]) * scale
    np.testing.assert_allclose(v[0], expected, atol=0.5)


def test_both_feature_rows_follow_the_database_sign() -> None:
    r = renderer([mat("slow", 2000.0, 0.8)], noise=False)
    c = ev.capture(r, "slow", 0.0, STAGE, seed=1)
    f = ev.feature_both(c)
    d80, d16, d120 = c.depth_mm
    np.testing.assert_allclose(f[0], d16 - d120, rtol=1e-6)
    np.testing.assert_allclose(f[1], d80 - d120, rtol=1e-6)
    # A slow subsurface response delays 16 MHz relatively more than 120 MHz saturates: row 0 > 0.
    assert np.nanmean(f[0]) > 1.0


def test_distinct_materials_are_all_recognised_leave_one_orientation_out() -> None:
    mats = [mat("fast", 5.0, 0.3), mat("mid", 300.0, 0.6), mat("slow", 3000.0, 0.9)]
    r = renderer(mats)
    result, caps = ev.evaluate(r, [m["name"] for m in mats], orientations=(0.0, 20.0, 40.0), stage_mm=STAGE, seed=3)
    assert len(caps) == 9
    for name in ("both", "depth", "frequency"):
        conf = result.confusion[name]
        assert conf.shape == (3, 3) and conf.sum() == 9
    assert result.accuracy["both"] == pytest.approx(100.0)
    assert ev.top_confusions(result, "both") == []


def test_fixed_backend_is_compared_on_the_same_queries() -> None:
    mats = [mat("fast", 5.0, 0.3), mat("mid", 300.0, 0.6), mat("slow", 3000.0, 0.9)]
    r = renderer(mats)
    result, _ = ev.evaluate(r, [m["name"] for m in mats], orientations=(0.0, 20.0, 40.0), stage_mm=STAGE, seed=3,
                            compare_fixed=True)  # fmt: skip
    assert sorted(result.fixed_disagreements) == sorted(result.accuracy)  # every feature
    # Distinct materials: far from any tie, the two backends label every query alike.
    assert all(d == [] for d in result.fixed_disagreements.values())
    plain, _ = ev.evaluate(r, [m["name"] for m in mats], orientations=(0.0, 20.0, 40.0), stage_mm=STAGE, seed=3)
    assert plain.fixed_disagreements == {}
    # Identical materials: any disagreement must be a near tie of the float path.
    same = renderer([mat("a", 300.0, 0.6), mat("b", 300.0, 0.6)])
    tied, _ = ev.evaluate(same, ["a", "b"], orientations=(0.0, 30.0), stage_mm=STAGE, seed=5, compare_fixed=True)
    for differ in tied.fixed_disagreements.values():
        for _, _, a, b, margin in differ:
            assert a != b and 0.0 <= margin < 0.05


def test_identical_materials_are_confused_not_crashed() -> None:
    mats = [mat("a", 300.0, 0.6), mat("b", 300.0, 0.6)]
    r = renderer(mats)
    result, _ = ev.evaluate(r, ["a", "b"], orientations=(0.0, 30.0), stage_mm=STAGE, seed=5)
    # Same physics: the nearest neighbour is a coin toss, never far above chance.
    assert result.accuracy["both"] <= 75.0


def test_stability_distance_grows_with_orientation_and_has_a_bound() -> None:
    mats = [mat("fast", 5.0, 0.3), mat("slow", 3000.0, 0.9)]
    r = renderer(mats, noise=False)
    s = ev.stability(r, ["fast", "slow"], "slow", [0.0, 40.0, 80.0], False, STAGE, seed=1)
    assert s["distance"][0] == pytest.approx(0.0, abs=1e-6)  # same geometry, no noise
    assert s["distance"][2] > s["distance"][1] > 0.0
    assert s["upper_bound"] > s["distance"][1]


def test_session_offsets_shift_the_rows_and_cancel_in_eq11() -> None:
    r = renderer([mat("wax", 300.0, 0.6)], noise=False)
    c = ev.capture(r, "wax", 0.0, STAGE, seed=2)
    s = ev.with_session_offsets(c, (2.5, -0.75))
    diff = ev.feature_both(s) - ev.feature_both(c)
    np.testing.assert_allclose(diff, np.broadcast_to([[2.5], [-0.75]], diff.shape), atol=1e-4)
    for g in range(3):
        np.testing.assert_allclose(ev.feature_depth(s, g, 10), ev.feature_depth(c, g, 10), atol=1e-4)
    np.testing.assert_array_equal(c.depth_mm, ev.capture(r, "wax", 0.0, STAGE, seed=2).depth_mm)  # not modified


def test_session_offset_spread_is_a_robust_sd_of_the_fitted_offsets() -> None:
    offs = [[0.0, 0.0], [1.0, -1.0], [-1.0, 1.0], [2.0, 0.5], [-2.0, -0.5], [100.0, 50.0]]  # one wild capture
    lib = {"materials": [{"name": f"m{i}", "fit": {"offsets_mm": o}} for i, o in enumerate(offs)]}
    s0, s1 = ev.session_offset_spread(lib)
    assert s0 == pytest.approx(1.4826 * 1.5) and s1 == pytest.approx(1.4826 * 0.75)
    assert ev.session_offset_spread({"materials": [{"name": "a"}]}) == (0.0, 0.0)


def test_session_offsets_make_frequency_features_harder_but_not_depth_ones() -> None:
    mats = [mat("a", 150.0, 0.5), mat("b", 200.0, 0.5), mat("c", 260.0, 0.5)]
    r = renderer(mats, noise=False)
    names = [m["name"] for m in mats]
    clean, _ = ev.evaluate(r, names, orientations=(0.0, 15.0, 30.0), stage_mm=STAGE, seed=4)  # type: ignore[misc]
    shifted, _ = ev.evaluate(
        r,
        names,
        orientations=(0.0, 15.0, 30.0),
        stage_mm=STAGE,
        seed=4,  # type: ignore[misc]
        session_offsets_mm=(8.0, 2.0),
    )
    assert shifted.accuracy["frequency"] < clean.accuracy["frequency"]
    assert shifted.accuracy["depth"] == clean.accuracy["depth"]


def test_session_state_spread_is_a_robust_sd_per_group() -> None:
    states = [[0.0, 0.0, 0.0], [1.0, -2.0, 0.5], [-1.0, 2.0, -0.5], [9.0, 9.0, 9.0], [0.5, 1.0, 0.25]]
    lib = {"materials": [{"name": f"m{i}", "fit": {"session": t}} for i, t in enumerate(states)]}
    sd = ev.session_state_spread(lib)
    # medians 0.5, 1, 0.25; median absolute deviations 0.5, 1, 0.25 (the wild capture ignored)
    assert sd == pytest.approx((1.4826 * 0.5, 1.4826 * 1.0, 1.4826 * 0.25))
    assert ev.session_state_spread({"materials": [{"name": "a", "fit": {}}]}) == (0.0, 0.0, 0.0)


def test_session_drift_renders_each_capture_in_its_own_session() -> None:
    mats = [mat("a", 150.0, 0.5), mat("b", 200.0, 0.5)]
    r = renderer(mats, noise=False)
    dev = r.device.to_dict()
    for f in dev["frequencies"]:
        f["session_drift"] = [{"h": h, "amplitude": 0.02, "phase_rad": 0.3 * h} for h in (2, 4, 5, 7)]
    drifting = sim.Renderer(sim.DeviceProfile.from_dict(dev), r.library)
    states: list[tuple[float, float, float]] = []

    def in_session(t: tuple[float, float, float]) -> sim.Renderer:
        states.append(t)
        return sim.Renderer(drifting.device.in_session(t), r.library)

    names = ["a", "b"]
    orient = (0.0, 15.0)
    plain, caps0 = ev.evaluate(drifting, names, orientations=orient, stage_mm=STAGE, seed=3)
    moved, caps1 = ev.evaluate(drifting, names, orientations=orient, stage_mm=STAGE, seed=3,
                               session_drift_sd=(1.0, 1.0, 1.0), session_renderer=in_session)  # fmt: skip
    assert len(states) == 4 and len(set(states)) == 4  # one session per capture, drawn afresh
    for key in caps0:  # the distortion's shape changed, so the depth feature (Eq. 11) moves too
        d = ev.feature_depth(caps1[key], 0, 10) - ev.feature_depth(caps0[key], 0, 10)
        assert np.nanmax(np.abs(d)) > 0.01, key
    # seeded: the same states again
    again: list[tuple[float, float, float]] = []
    ev.evaluate(drifting, names, orientations=orient, stage_mm=STAGE, seed=3, session_drift_sd=(1.0, 1.0, 1.0),
                session_renderer=lambda t: (again.append(t), in_session(t))[1])  # fmt: skip
    assert again == states[:4]
    with pytest.raises(ValueError, match="session_renderer"):
        ev.evaluate(drifting, names, orientations=orient, stage_mm=STAGE, session_drift_sd=(1.0, 0.0, 0.0))
    assert plain.accuracy.keys() == moved.accuracy.keys()


@pytest.mark.parametrize("option,value,message", [
    ("--session-drift", "1,2", "three finite"),
    ("--session-drift", "1,nan,2", "three finite"),
    ("--session-drift", "1,-1,2", "three finite"),
    ("--session-drift", "a,b,c", "expected none, library or S80,S16,S120"),
    ("--session-offsets", "1", "expected none, library or S0,S1"),
    ("--session-offsets", "1,-2", "finite and >= 0"),
])  # fmt: skip
def test_evaluate_cli_rejects_bad_session_options(option: str, value: str, message: str) -> None:
    from click.testing import CliRunner

    from tofmat.cli import main

    r = CliRunner().invoke(main, ["sim", "evaluate", "--materials", "cork", option, value])
    assert r.exit_code == 2 and message in r.output, r.output


def test_the_papers_protocol_runs_on_the_whole_library_with_more_exemplars_than_a_table_holds() -> None:
    # 29 materials x 9 training orientations = 261 exemplars: more than a table's 255 materials, so
    # the nearest neighbour runs over one table per training orientation (it once failed with
    # "too many materials: 348"). The nearest exemplar's material is the label either way: checked
    # against a brute-force Eq. (12) over every exemplar.
    r = sim.Renderer(sim.load_device(), sim.load_library())
    names = list(r.library.names)
    assert len(names) == 29
    orient = tuple(float(a) for a in range(0, 50, 5))
    result, caps = ev.evaluate(r, names, orientations=orient, stage_mm=np.arange(600.0, 1250.0 + 1e-9, 25.0), seed=1)
    assert len(caps) == 29 * 10
    for name, conf in result.confusion.items():
        assert conf.sum() == 29 * 10, name
    feature = ev.feature_functions(27)["both"]
    feats = {k: feature(c) for k, c in caps.items()}
    wrong = 0
    for held in orient:
        for truth in names:
            q = feats[(truth, held)]
            best = min((ev.eq12(q, feats[(m, o)]), m) for m in names for o in orient if o != held)[1]
            wrong += best != truth
    assert 100.0 * (29 * 10 - wrong) / (29 * 10) == pytest.approx(result.accuracy["both"])
    assert result.accuracy["both"] > 70.0
