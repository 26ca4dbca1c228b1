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
    shifted, _ = ev.evaluate(r, names, orientations=(0.0, 15.0, 30.0), stage_mm=STAGE, seed=4,  # type: ignore[misc]
                             session_offsets_mm=(8.0, 2.0))
    assert shifted.accuracy["frequency"] < clean.accuracy["frequency"]
    assert shifted.accuracy["depth"] == clean.accuracy["depth"]
