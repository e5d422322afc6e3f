"""The model chosen by the data: each rule recovers the true model of a sensor made to have it."""
from dataclasses import replace

import numpy as np
import pytest

from tof_calib_ros import Board, View, calibrate, sim
from tof_calib_ros.core import camera as cam
from tof_calib_ros.core import depth_bias, model_choice, pipeline
from tof_calib_ros.core.result import MAX_FOCAL_REL_STD
from tof_calib_ros.sim import bound, scenes

BOARD = Board(11, 11, 0.05)
F = 284.4


def _views(params, n_img, n_corn, seed, tilt=40.0, noise=None, depth_tilt=(0.0, 0.0), corner_noise=0.01,
           radial_offset=0.0):
    """The paper's protocol: ``n_corn`` corners spread over the board, 0.01 px corner noise."""
    camera = sim.SimCamera(np.asarray(params, dtype=float), 200, 200)
    rng = np.random.default_rng(seed)
    poses = sim.random_poses(camera, BOARD, n_img, rng, distance=(0.9, 1.4), max_tilt_deg=tilt)
    k = int(round(np.sqrt(n_corn)))
    sel = np.round(np.linspace(0, BOARD.cols - 1, k)).astype(int)
    ids = np.array([r * BOARD.cols + c for r in sel for c in sel])
    xs, ys = np.meshgrid(np.arange(200.0), np.arange(200.0))
    ray = cam.rays(np.column_stack([xs.ravel(), ys.ravel()]), camera.params).reshape(200, 200, 3)
    views = []
    for rvec, tvec in poses:
        f = sim.render(camera, BOARD, rvec, tvec, noise=noise or sim.Noise(depth=0.005), rng=rng)
        # a depth axis off the optical axis: the depth reads tilt_x * X + tilt_y * Y more
        depth = f.depth + depth_tilt[0] * ray[..., 0] * f.depth_true + depth_tilt[1] * ray[..., 1] * f.depth_true
        # an offset in the light's path: in z-depth, the same along each ray and less towards the edges
        depth = depth + radial_offset / np.linalg.norm(ray, axis=-1)
        views.append(View(depth, f.corners[ids] + rng.normal(0, corner_noise, (len(ids), 2)), ids))
    return views


@pytest.mark.parametrize("lens, expected", [
    ((0, 0, 0, 0, 0), {"none"}),
    ((-0.3, 0, 0, 0, 0), {"k1"}),
    ((-0.3, 0.1, 0, 0, 0), {"k1k2", "plumb_bob"}),
])
def test_the_distortion_terms_the_lens_has(lens, expected):
    views = _views([F, F, 99.5, 99.5, *lens], 6, 25, seed=3)
    res = calibrate(views, BOARD)
    assert res.model.distortion in expected, res.model.reasons
    assert res.K[0, 0] == pytest.approx(F, abs=3 * res.std["fx"] + 0.05)
    # and not by a wide sigma: trusted, 0.03-0.08 % off, stated +- 0.08-0.11 px (2026-11-29)
    assert res.ok and abs(res.K[0, 0] / F - 1) < 0.002 and res.std["fx"] < 0.3, (res.K[0, 0], res.std["fx"])


# The Azure Kinect depth camera's own lens in its wide mode (its factory model, rational, binned
# to 512x512): 120 degrees, 250 px of barrel at the corners, which no plumb_bob holds to a pixel.
WIDE = [252.0, 252.0, 256.5, 254.5, 4.7247, 3.2092, 1.2e-4, 5.9e-6, 0.1706, 5.0559, 4.7758, 0.8865]


def _azure_views(camera: sim.SimCamera, board: Board, seed: int, distance: tuple[float, float]) -> list[View]:
    """16 views as `wide_lens.py` renders them (its seeds): 0.05 px of corner noise, 3 mm of
    depth noise and a 10 mm offset."""
    rng = np.random.default_rng(seed)
    views = []
    for rvec, tvec in sim.random_poses(camera, board, 16, rng, distance=distance):
        f = sim.render(camera, board, rvec, tvec, noise=sim.Noise(depth=0.003, offset=0.01), rng=rng)
        views.append(View(f.depth, f.corners + rng.normal(0, 0.05, f.corners.shape)))
    return views


@pytest.mark.slow
def test_a_wide_lens_no_polynomial_holds_is_calibrated_as_rational_and_refused_in_a_polynomial():
    camera = sim.SimCamera(np.array(WIDE), 512, 512)
    board = Board(8, 6, 0.05)
    views = _azure_views(camera, board, 3, (0.35, 0.9))
    # the defaults: k3 folds the polynomial back inside the image, and the rational lens pays
    res = calibrate(views, board)
    assert res.model.distortion == "rational" and res.ok, (res.model.reasons, res.verdict)
    # taken where k3 folds, or else by the corners' lens misfit: on an AMD EPYC machine the rational
    # lens's refits without a fold of the views ran off (fx 581-1437 px for 248) from the first
    # round's noise, so its held-out deviance refused it, and the misfit took it. Refitted from the
    # fit's own noise where they end worse than they started, they stayed at 251-252 px (ci76), but
    # a later run of the same code on the same machine took the misfit's path again (ci77, 2026-12-02)
    assert any(r.startswith(("rational lens: with k3 the polynomial folds back",
                             "rational lens: the corners alone fit it")) for r in res.model.reasons), res.model.reasons
    # the depth samples chosen through OpenCV's plumb_bob took in the wall beside the edge views'
    # boards (one view's corners 1.2 m off in depth, refused, 2026-11-30): chosen again through the
    # lens the fit chose, every view's depth fits its corners
    assert any("the samples were chosen again through it" in r for r in res.model.reasons), res.model.reasons
    depth_rms = np.array([v.depth_rms for v in res.views])
    assert np.nanmax(depth_rms) < 0.002, depth_rms
    truth = camera.params[:4]
    est = np.r_[res.K[0, 0], res.K[1, 1], res.K[0, 2], res.K[1, 2]]
    assert np.all(np.abs(est - truth) < 3 * np.array([res.std[n] for n in ("fx", "fy", "cx", "cy")]) + 0.05), est
    # every pixel the views reached projects where the lens puts it; ROS's plumb_bob (OpenCV on the
    # same corners) misses by pixels
    reached = np.concatenate([v.corners for v in views])
    rays = cam.rays(reached, camera.params)
    ours = cam.project(rays, cam.pack_intrinsics(res.K, res.D)).pixels
    opencv = calibrate(views, board, method="traditional")
    theirs = cam.project(rays, cam.pack_intrinsics(opencv.K, opencv.D)).pixels
    ours_err, their_err = (np.linalg.norm(p - reached, axis=1) for p in (ours, theirs))
    assert np.median(ours_err) < 0.1 and np.median(their_err) > 10 * np.median(ours_err), (ours_err, their_err)
    assert res.to_dict()["distortion_model"] == "rational_polynomial" and res.D.size == 8
    assert res.lens_rms is None
    # a square size 10 % too large is refused, in the rational lens: the depth fighting the corners
    # left the lens chosen in a polynomial, which the corners alone did not hold, and the verdict
    # asked for the rational lens (2026-11-30)
    # On the AMD EPYC machine of 2026-12-02 the samples chosen again through the
    # rational lens chose full, which fits the corners as closely (0.0685 against 0.0683 px), and
    # it was refused for fx and fy poorly constrained (7.9 px), not for the square size
    wrong = calibrate(views, Board(8, 6, 0.055))
    assert wrong.model.distortion in ("rational", "full") and not wrong.ok, (wrong.model.reasons, wrong.verdict)
    # a polynomial asked for is refused, saying why
    full = calibrate(views, board, distortion="full")
    assert not full.ok and full.verdict[0].startswith("the lens bends more than full can follow"), full.verdict
    assert full.to_dict()["lens_rms_px"]["chosen"] > 2 * full.lens_rms[1]


@pytest.mark.slow
def test_a_wide_lens_with_a_square_size_10_percent_too_small_is_not_trusted():
    """The wide lens, `wide_lens.py`'s seed 2, told 45 mm squares for 50 mm: trusted before
    2026-11-30 (f083980), refused since, for the square size."""
    camera = sim.SimCamera(np.array(WIDE), 512, 512)
    board = Board(8, 6, 0.05)
    views = _azure_views(camera, board, 2, (0.35, 0.9))
    wrong = calibrate(views, Board(8, 6, 0.045))
    assert not wrong.ok, (wrong.K[0, 0], wrong.std["fx"], wrong.model.reasons)
    # and for what it is: the lens turned rational only as the depth yielded, and the corners-alone
    # reference stayed OpenCV's plumb_bob (fx +- 3.5 px), refusing it as poorly constrained
    assert wrong.model.distortion == "rational" and "the squares look larger than the size given" in wrong.verdict[0]
    assert wrong.depth_square == pytest.approx(0.05, rel=0.01), wrong.depth_square


@pytest.mark.slow
@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_a_lens_whose_k3_folds_in_the_image_is_calibrated_as_rational_on_the_defaults():
    """The Azure Kinect's narrow mode (640x576, its factory rational lens): plumb_bob with k3 holds
    it to about 0.1 px but folds back 425 px out, inside the image; without k3 the pixels the views
    reached came out 0.3 px off and fx 1.6 stated sigmas (2026-11-30). The rational lens, which
    pays on the views and on views left out, is taken instead."""
    camera = sim.SimCamera(np.r_[504.0, 504.0, 321.5, 329.0, WIDE[4:]], 640, 576)
    board = Board(8, 6, 0.05)
    views = _azure_views(camera, board, 1, (0.6, 1.6))
    res = calibrate(views, board)
    assert res.model.distortion == "rational" and res.ok, (res.model.reasons, res.verdict)
    assert any(r.startswith("rational lens: with k3 the polynomial folds back") for r in res.model.reasons)
    assert res.model.evidence["rational"]["held_out_gain"] > res.model.evidence["rational"]["price"]
    truth = camera.params[:4]
    est = np.r_[res.K[0, 0], res.K[1, 1], res.K[0, 2], res.K[1, 2]]
    assert np.all(np.abs(est - truth) < 3 * np.array([res.std[n] for n in ("fx", "fy", "cx", "cy")])), est
    reached = np.concatenate([v.corners for v in views])
    off = np.linalg.norm(cam.project(cam.rays(reached, camera.params), cam.pack_intrinsics(res.K, res.D)).pixels
                         - reached, axis=1)
    assert np.median(off) < 0.15, np.median(off)   # 0.07 px (2026-11-30); without k3, 0.3 px
    # the rational terms trade (numerator against denominator): unconstrained one by one, their
    # variance infinite, which made the others' NaN (and numpy's warnings) until 2026-11-30
    assert not np.isnan(list(res.std.values())).any(), res.std
    assert all(np.isfinite(res.std[n]) for n in ("fx", "fy", "cx", "cy", "p1", "p2")), res.std


@pytest.mark.slow
def test_four_corners_three_images_with_a_real_lens():
    """Where OpenCV refuses (4 corners x 3 images) and a strong lens: the depth fixes the poses,
    so distortion is observable. Over twelve seeds a trusted focal length is within 2 % and
    within 5 of its stated sigmas, and at most one lies beyond 3 (the score test alone, which
    understates a term whose absence inflates the noise, trusted one 2.8 % off at 11 sigmas and
    two beyond 3). An untrusted one says why."""
    beyond, trusted = [], 0
    for seed in range(1, 13):
        res = calibrate(_views([F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0], 3, 4, seed), BOARD)
        if not res.ok:
            assert any("poorly constrained" in r for r in res.verdict), res.verdict
            continue
        trusted += 1
        z = abs(res.K[0, 0] - F) / res.std["fx"]
        assert abs(res.K[0, 0] / F - 1) < 0.02 and z < 5, (seed, res.K[0, 0], res.std["fx"], res.model.reasons)
        beyond += [seed] if z > 3 else []
    assert len(beyond) <= 1, beyond
    assert trusted >= 6, trusted   # not a pass by refusing: 9 of the 12 trusted (2026-11-29)


@pytest.mark.parametrize("depth_tilt, chosen", [((0.0, 0.0), False), ((0.02, -0.015), True)])
def test_the_depth_tilt_is_taken_when_the_sensor_has_it(depth_tilt, chosen):
    views = _views([F, F, 99.5, 99.5, 0, 0, 0, 0, 0], 6, 25, seed=4, depth_tilt=depth_tilt)
    res = calibrate(views, BOARD)
    assert ("tilt" in res.model.depth_bias.split("+")) == chosen, res.model.reasons
    if chosen:
        assert res.depth_bias[2:4] == pytest.approx(depth_tilt, abs=0.003)
    assert res.K[0, 2] == pytest.approx(99.5, abs=1.0) and res.K[1, 2] == pytest.approx(99.5, abs=1.0)


@pytest.mark.slow
@pytest.mark.parametrize("offset", [0.05, 0.0])
def test_a_radial_offset_is_told_from_a_wiggle_near_frontal(offset):
    """A 50 mm offset in the light's path bows every near-frontal board's z-depth alike, deeper
    towards the image's edges. Without a radial term one of these four seeds took the bow for a
    wiggle and was trusted 4.4 % off at 18 sigmas; the other three were refused. The radial term
    is chosen in three, where it gains no less than a wiggle would (in the fourth a wiggle at the
    longest period gains 1.5 more: none is taken, as before), recovers the offset to 5 mm and fx
    to 0.06 %. Near frontal a wiggle's bows are alike too, and its slope is a depth scale, so fx's
    uncertainty carries one, and the wiggles that gain about as much (1.7-8.1 px, the corners
    alone 2.0-5.7): none is beyond 2 stated sigmas. Without the offset it is not chosen."""
    lens = [F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0]
    radial, chosen = depth_bias.TERMS["radial"][0], 0
    for seed in range(4):
        views = _views(lens, 6, 25, seed=100 * seed + 11, tilt=5.0, noise=sim.Noise(depth=0.005),
                       radial_offset=offset)
        res = calibrate(views, BOARD)
        assert res.model.wiggle_period is None, (seed, res.model.reasons)
        assert abs(res.K[0, 0] / F - 1) < 0.001 and abs(res.K[0, 0] - F) < 2 * res.std["fx"], (seed, res.K[0, 0])
        assert res.ok or offset, (seed, res.verdict)
        if "radial" in res.model.depth_bias.split("+"):
            assert res.depth_bias[radial] == pytest.approx(offset, abs=0.006), (seed, res.depth_bias)
            chosen += 1
    assert chosen >= 3 if offset else chosen == 0, chosen


@pytest.mark.parametrize("seed, n_img, n_corn", [(5, 4, 9), (2, 4, 4), (5, 4, 4)])
def test_a_wiggle_taken_for_a_radial_offset_leaves_fx_within_its_sigmas(seed, n_img, n_corn):
    """Near frontal, few views of a 15 mm wiggle can bow alike, and a radial offset then gains a
    little more than the wiggle (1.3-4.9 here): taken, fx keeps the wiggle's slope, 4.9 % off.
    The wiggle's fits weighed 1/n of the offset's in fx's uncertainty, and one of these was 2.3
    stated sigmas off; weighed as the same family at one price, they carry fx's uncertainty to
    10-11 px, and the result is refused."""
    lens = [F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0]
    noise = sim.Noise(depth=0.01, wiggle_amplitude=0.015, wiggle_period=1.87,
                      wiggle_phase=2 * np.pi * ((seed * 0.37) % 1))
    res = calibrate(_views(lens, n_img, n_corn, seed=seed, tilt=5.0, noise=noise), BOARD)
    assert "radial" in res.model.depth_bias.split("+"), res.model.reasons
    assert abs(res.K[0, 0] - F) < 2 * res.std["fx"], (res.K[0, 0], res.std["fx"])
    assert not res.ok or abs(res.K[0, 0] / F - 1) < 0.01, (res.K[0, 0], res.verdict)


def test_fx_sigma_weighs_the_depth_models_about_the_one_fitted(monkeypatch):
    """The yield loop chooses the depth model again at a lighter depth weight, and may drop a
    radial offset the search took: fx's uncertainty is then the average about the model actually
    fitted (its free terms say which), not about the one the search took. Here nothing is taken;
    told that the search took the radial offset, the average must come out the same."""
    from tof_calib_ros.core import bundle
    seen = []
    original = pipeline.over_wiggles
    monkeypatch.setattr(pipeline, "over_wiggles", lambda *a: seen.append(a) or original(*a))
    lens = [F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0]
    noise = sim.Noise(depth=0.01, wiggle_amplitude=0.015, wiggle_period=1.87, wiggle_phase=1.0)
    calibrate(_views(lens, 3, 9, seed=1, tilt=5.0, noise=noise), BOARD)
    observations, fit, free, options, search, searched = seen[0]
    assert search.radial_gain is not None and search.refit is None, search.evidence
    assert bundle.RADIAL not in free and bundle.WIGGLE[0] not in free, free
    told = replace(search, radial=True, refit=object())
    fitted = original(observations, fit, free, options, search, searched).covariance
    assert not np.allclose(fitted, fit.covariance)   # the other models do widen it
    np.testing.assert_allclose(original(observations, fit, free, options, told, searched).covariance, fitted,
                               rtol=1e-9)


def _widen_at_full_weight(monkeypatch) -> None:
    """What the depth's model leaves open made ten times fx's own uncertainty, at the depth's full
    weight only."""
    original = pipeline._widened

    def widened(observations, fit, *rest):
        stated, why = original(observations, fit, *rest)
        if observations[0].depth_inflation == 1.0:
            stated = replace(stated, covariance=100 * stated.covariance)
        return stated, why

    monkeypatch.setattr(pipeline, "_widened", widened)


def _unexplained_over_distance(monkeypatch) -> None:
    """The depth check finds the depth's error over distance unexplained."""
    check = pipeline.depth_check
    monkeypatch.setattr(pipeline, "depth_check", lambda *a: replace(check(*a), over_distance=True))


def test_the_depth_yields_where_what_its_model_leaves_open_makes_fx_less_certain_than_the_corners(monkeypatch):
    """Where the depth's error follows the distance in a way the model does not explain, the yield
    is judged on the uncertainty the result states, which adds what the depth's model leaves open
    (a scale the corners fix, the wiggles the data leave likely) to the fit's own: real Kinect v2
    views at 205x170 stated 145.6 +- 2.7 px with the depth at its full weight, the corners alone
    148.3 +- 1.2. Here that widening is made ten times fx's own uncertainty at the depth's full
    weight only. Where the model explains the depth, the widening alone does not make it yield
    (near frontal, a radial offset modelled was 0.06 % off, and the corners alone 2.7 %); where
    the depth check finds the error over distance unexplained, the depth yields once, and says why."""
    views = _views([F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0], 5, 16, seed=3, noise=sim.Noise(depth=0.01))
    plain = calibrate(views, BOARD)
    assert plain.model.depth_inflation == 1.0, plain.model.reasons
    _widen_at_full_weight(monkeypatch)
    explained = calibrate(views, BOARD)
    assert explained.model.depth_inflation == 1.0, explained.model.reasons
    assert explained.std["fx"] > 5 * plain.std["fx"]   # the widening is there, and stated
    _unexplained_over_distance(monkeypatch)
    res = calibrate(views, BOARD)
    assert res.model.depth_inflation == pipeline.DEPTH_INFLATION_STEP, res.model.reasons
    assert any("with what its model leaves open, left f" in r and "less certain than the corners alone" in r
               for r in res.model.reasons), res.model.reasons
    assert abs(res.K[0, 0] - F) < 2 * res.std["fx"], (res.K[0, 0], res.std["fx"])


def test_the_depth_is_judged_against_the_corners_in_its_own_lens(monkeypatch):
    """The yield's reference, the corners alone, is fitted in the lens the result has: a k3 (here
    asked for) leaves fx less certain than plumb_bob's corners however far the depth yields, and
    against those the depth yielded to 64 times its noise, its most, where once was enough."""
    views = _views([F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0], 5, 16, seed=3, noise=sim.Noise(depth=0.01))
    plumb_bob = calibrate(views, BOARD, distortion="plumb_bob", method="traditional")
    _widen_at_full_weight(monkeypatch)
    _unexplained_over_distance(monkeypatch)
    res = calibrate(views, BOARD, distortion="full")
    assert res.model.distortion == "full"
    assert res.model.depth_inflation == pipeline.DEPTH_INFLATION_STEP, res.model.reasons
    assert res.corner_focal[2] > plumb_bob.std["fx"], (res.corner_focal, plumb_bob.std)   # the reference has k3
    assert res.corner_lens == "full" and "(full, on the noise of each)" in res.gain_brief()
    assert abs(res.K[0, 0] - F) < 3 * res.std["fx"], (res.K[0, 0], res.std["fx"])


@pytest.mark.slow
def test_a_wiggling_depth_yields_to_the_corners():
    """15 mm of wiggling (a sinusoid of the distance, 1.87 m period, its phase drawn per seed):
    over the distances seen its slope reads as a depth scale of a few percent, which the depth
    alone puts in the focal length. Where the corners see that level, a scale term takes it and
    the corners fix it: over six seeds the focal error is a fraction of what the offset-only model
    says with the depth at its full weight (before it yields to the corners, which it now does
    where the depth leaves fx less certain than they do)."""
    ours, offset_only = [], []
    for seed in range(6):
        rng = np.random.default_rng(seed)
        noise = sim.Noise(depth=0.01, wiggle_amplitude=0.015, wiggle_period=1.87, wiggle_phase=rng.uniform(0, 6.28))
        views = _views([F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0], 6, 16, seed=100 * seed + 5, noise=noise)
        res = calibrate(views, BOARD)
        ours.append(abs(res.K[0, 0] / F - 1))
        full = calibrate(views, BOARD, depth_bias="offset").to_dict()["depth_full_weight_focal"]["fx"]
        offset_only.append(abs(full / F - 1))
        doc = res.to_dict()   # the result carries its model, and each view's plane as data
        assert doc["model"]["depth_bias"] == res.model.depth_bias and len(doc["views"][0]["plane"]) == 3
    assert np.median(ours) < 0.003 and np.median(ours) < 0.5 * np.median(offset_only), (ours, offset_only)


@pytest.mark.slow
def test_a_wiggling_depth_leaves_the_focal_length_within_its_sigmas():
    """General poses, 15 mm of wiggling, no modulation frequency: where the depth's level departs
    from the corners' by 2 standard errors, the scale term takes it. Over ten seeds the true fx
    lies beyond 2 stated sigmas in at most 2 (measured: 1; at 5 standard errors with the level as
    the scale's prior, 4, up to 7.8 sigmas off)."""
    beyond = []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        noise = sim.Noise(depth=0.01, wiggle_amplitude=0.015, wiggle_period=1.87, wiggle_phase=rng.uniform(0, 6.28))
        views = _views([F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0], 5, 36, seed=100 * seed + 7, noise=noise)
        res = calibrate(views, BOARD)
        z = (res.K[0, 0] - F) / res.std["fx"]
        assert abs(res.K[0, 0] / F - 1) < 0.005, (seed, res.K[0, 0], res.model.reasons)
        beyond += [(seed, round(z, 1))] if abs(z) > 2 else []
    assert len(beyond) <= 2, beyond


@pytest.mark.slow
def test_a_depth_that_pulls_the_corners_off_their_fit_gives_way_to_them():
    """General poses, 4 corners a view, 15 mm of wiggling, and a depth model without the wiggle:
    what the model cannot take of it pulls the camera off what the corners say (they fit 10-70
    times worse than alone) and the depth at its full weight puts fx 0.5-4 % off. Its weight
    falls until the corners fit about as well: over eight seeds each result is within 0.5 % and 2
    stated sigmas, and it keeps what the depth at its full weight said. (On its defaults ours
    finds the wiggle in these views and models it: test_the_wiggle_and_its_period_are_chosen...)"""
    full = []
    for seed in range(8):
        rng = np.random.default_rng(seed)
        noise = sim.Noise(depth=0.01, wiggle_amplitude=0.015, wiggle_period=1.87, wiggle_phase=rng.uniform(0, 6.28))
        res = calibrate(_views([F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0], 5, 4, 100 * seed + 9, noise=noise), BOARD,
                        depth_bias="offset+tilt")
        assert res.model.depth_inflation > 1
        assert any("fit worse with the depth at its full weight" in r for r in res.model.reasons), res.model.reasons
        assert abs(res.K[0, 0] / F - 1) < 0.005 and abs(res.K[0, 0] - F) < 2 * res.std["fx"], (seed, res.K[0, 0])
        full.append(abs(res.to_dict()["depth_full_weight_focal"]["fx"] / F - 1))
    assert np.median(full) > 0.01, full   # the depth alone was off: the corners made the difference


@pytest.mark.slow
def test_a_depth_error_of_each_views_own_yields_to_the_corners():
    """Each view's depth off by its own offset (20 mm, 10 mm apart from view to view; 8 views in
    general poses): no model term takes it. Before the depth yielded to it, its fx moved by
    7.6-12 px over folds of the views where the corners alone say 1.0-1.4, and 4 of these 4
    seeds were refused (one 4 % off). Its weight now falls until fx is no less certain than from
    the corners alone: measured within 0.2-0.8 stated sigmas, sigma 1.0-2.4 px (seed 0, left
    out, is trusted 2.1 sigmas off, a spread the folds do not see). With no such error the depth
    keeps its full weight and fx's sigma is 2-7 times below the corners'."""
    camera, board = sim.pmd_camera(), Board(5, 7, 0.03)
    for spread in (0.01, 0.0):
        for seed in range(1, 5):
            rng = np.random.default_rng(seed)
            views = []
            for rvec, tvec in sim.random_poses(camera, board, 8, rng, distance=(0.4, 0.9), max_tilt_deg=40):
                noise = sim.Noise(depth=0.002, offset=0.02 + spread * rng.standard_normal(), invalid_fraction=0.002)
                f = sim.render(camera, board, rvec, tvec, noise=noise, rng=rng)
                views.append(View(f.depth, f.corners + rng.normal(0, 0.05, f.corners.shape), None))
            res = calibrate(views, board)
            alone = res.to_dict()["corner_only_focal"]["std_fx"]
            assert (res.model.depth_inflation > 1) == (spread > 0), (spread, seed, res.model.reasons)
            assert abs(res.K[0, 0] - F) < 2 * res.std["fx"], (spread, seed, res.K[0, 0], res.std["fx"])
            if spread:
                assert res.std["fx"] < 2 * alone, (seed, res.std["fx"], alone)
                assert any("less certain than the corners alone" in r or "fit worse" in r for r in res.model.reasons)
            else:
                assert res.std["fx"] < 0.5 * alone, (seed, res.std["fx"], alone)


@pytest.mark.slow
def test_a_near_frontal_wiggle_of_unknown_period_is_found_and_fx_is_within_its_sigmas():
    """Near frontal without the modulation frequency, a wiggle's slope is a depth scale the views
    cannot tell from the focal length. The search finds the wiggle by its curvature across the
    boards, and fx's uncertainty carries the fits at the periods the views cannot rule out. Over
    ten seeds the offset-only model trusted 9, 0.4-4.8 % off at 3.5-59 sigmas; the bow check that
    came before the search left 1 (the true fx within 2 sigmas in 5 of the 9 it saw bowed); now
    the wiggle is found in all ten and the true fx lies within 2 stated sigmas in all (measured
    0.1-1.8), 5 trusted. Without a wiggle none is found, and every result is trusted and within
    2 sigmas."""
    lens = [F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0]
    beyond = []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        for amplitude in (0.015, 0.0):
            noise = sim.Noise(depth=0.01, wiggle_amplitude=amplitude, wiggle_period=1.87,
                              wiggle_phase=rng.uniform(0, 6.28))
            res = calibrate(_views(lens, 5, 16, seed=100 * seed + 3, tilt=5.0, noise=noise), BOARD)
            z = abs(res.K[0, 0] - F) / res.std["fx"]
            if amplitude == 0:
                assert res.model.wiggle_period is None and res.ok and z < 2, (seed, res.model.reasons, z)
            else:
                assert res.model.wiggle_period is not None, (seed, res.model.reasons)
                beyond += [seed] if z > 2 else []
    assert len(beyond) <= 1, beyond


@pytest.mark.slow
def test_a_near_frontal_wiggle_the_search_leaves_out_still_counts_in_fx_sigma():
    """Three near-frontal views of 9 corners often cannot show a 15 mm wiggle: its gain falls
    short of its price, or peaks at the end of the periods looked for, and the model is chosen
    without it. fx's uncertainty then includes the fits with a wiggle at each period, as likely
    as the data make them. Over these eight seeds the wiggle is left out in five; counting only
    the fits at other periods when one was taken, two were trusted with the truth beyond 2
    stated sigmas (0.6 % off at 2.6 sigmas, 1.9 % off at 2.8); now none is, and every fx lies
    within 2 of its sigmas (measured 0.0-1.4)."""
    lens = [F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0]
    left_out = 0
    for seed in range(8):
        rng = np.random.default_rng(seed)
        noise = sim.Noise(depth=0.01, wiggle_amplitude=0.015, wiggle_period=1.87, wiggle_phase=rng.uniform(0, 6.28))
        res = calibrate(_views(lens, 3, 9, seed=100 * seed + 7, tilt=5.0, noise=noise), BOARD)
        z = abs(res.K[0, 0] - F) / res.std["fx"]
        assert z < 2, (seed, res.K[0, 0], res.std["fx"], res.model.reasons)
        if res.model.wiggle_period is None:
            left_out += 1
            assert res.std["fx"] > res.noise_std["fx"], (seed, res.std, res.noise_std)
    assert left_out >= 3, left_out


@pytest.mark.slow
@pytest.mark.parametrize("amplitude", [0.015, 0.0])
def test_the_wiggle_is_estimated_where_the_modulation_frequency_is_given(amplitude):
    """The modulation frequency gives the wiggle's period (1.87 m at 20 MHz); its amplitude and
    phase then come from the data: recovered to a few millimetres, and the focal length is as
    good as on a sensor that does not wiggle. Without the frequency, the default model puts
    the wiggle's slope in the focal length (a seed here ends 2 % off, refused)."""
    period = depth_bias.wiggle_period(20e6)
    for seed in range(4):
        rng = np.random.default_rng(seed)
        phase = rng.uniform(0, 2 * np.pi)
        noise = sim.Noise(depth=0.01, wiggle_amplitude=amplitude, wiggle_period=period, wiggle_phase=phase)
        views = _views([F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0], 6, 16, seed=100 * seed + 5, noise=noise)
        res = calibrate(views, BOARD, modulation_hz=20e6)
        assert "wiggle" in res.model.depth_bias.split("+") and res.ok, (res.model.reasons, res.verdict)
        truth = amplitude * np.array([np.cos(phase), np.sin(phase)])   # a sin(kr + phase) = a cos sin + a sin cos
        assert np.hypot(*(res.depth_bias[4:6] - truth)) < 0.005, (res.depth_bias, truth)
        assert abs(res.K[0, 0] / F - 1) < 0.003 and abs(res.K[0, 0] - F) < 3 * res.std["fx"] + 0.05, res.K[0, 0]


@pytest.mark.slow
@pytest.mark.parametrize("amplitude, n_img, n_corn", [(0.015, 6, 16), (0.0, 6, 16), (0.015, 5, 4)])
def test_the_wiggle_and_its_period_are_chosen_by_the_data(amplitude, n_img, n_corn):
    """Without the modulation frequency the default looks for a wiggle over the periods of 8 to
    130 MHz, and takes it where its gain (the score test's) exceeds the price of its sine,
    cosine and period. With 15 mm of wiggling (20 MHz, 1.87 m) it is taken, at a period within
    a candidate step of the truth (measured 1.85 and 1.47 m; gain 89-284 against 16), and fx
    lies within 2 stated sigmas; without, it is not (gain 1-4). At 4 corners a view too (where
    the model without it left the depth to yield: fx 0.5-4 % off at full weight). The result
    records the period as chosen, not as asked, and the options it repeats a calibration with
    carry it."""
    period = depth_bias.wiggle_period(20e6)
    for seed in range(4):
        rng = np.random.default_rng(seed)
        noise = sim.Noise(depth=0.01, wiggle_amplitude=amplitude, wiggle_period=period,
                          wiggle_phase=rng.uniform(0, 2 * np.pi))
        views = _views([F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0], n_img, n_corn, seed=100 * seed + 11,
                       noise=noise)
        res = calibrate(views, BOARD)
        evidence = res.model.evidence["wiggle"]
        assert res.ok and abs(res.K[0, 0] - F) < 2 * res.std["fx"], (seed, res.K[0, 0], res.std["fx"], res.verdict)
        assert abs(res.K[0, 0] / F - 1) < 0.005
        assert res.options.modulation_hz is None
        if amplitude:
            assert "wiggle" in res.model.depth_bias.split("+") and evidence["gain"] > evidence["price"]
            assert period / 1.3 < res.model.wiggle_period < period * 1.3, (seed, res.model.wiggle_period)
            assert res.options.fixed(res.model).wiggle_period == pytest.approx(res.model.wiggle_period)
        else:
            assert res.model.wiggle_period is None and evidence["gain"] < evidence["price"], (seed, evidence)


# A pico flexx class sensor, unlike the ones the defaults were tuned on (``sim.scenes.pico_flexx``).
PICO = sim.pico_flexx_camera().params


def _pico(seed: int) -> tuple[Board, list[View], float]:
    frames = scenes.pico_flexx(seed)
    return (scenes.PICO_BOARD, [View(f.depth, amplitude=f.amplitude) for f in frames],
            depth_bias.wiggle_period(scenes.PICO_MODULATION_HZ))


@pytest.mark.slow
def test_a_short_wiggle_of_a_low_resolution_sensor_is_found_from_its_amplitude_images():
    """The wiggle is found at a period within a candidate step (0.46 or 0.58 m in all of seeds
    1-16) and fx is within 1 % (0.99 % at worst over seeds 1-16); at most one of three seeds lies
    beyond 2 stated sigmas (a normal error does so 5 % of the time), none beyond 3. Each is
    trusted, but where the corners alone leave fx beyond the verdict's 1 % too: seed 3's folds
    of the views each choose the period all of them did (0.459 m) and still spread fx +- 3.6 px,
    where the corners alone say +- 2.9, and it is refused as poorly constrained (0.33 px off),
    the verdict putting that down to the views, not the period."""
    z = []
    for seed in range(1, 4):
        board, views, period = _pico(seed)
        res = calibrate(views, board)
        assert "wiggle" in res.model.depth_bias.split("+"), (seed, res.model.reasons)
        assert period / 1.3 < res.model.wiggle_period < period * 1.3, (seed, res.model.wiggle_period)
        error = res.K[0, 0] - PICO[0]
        assert abs(error) < 0.01 * PICO[0], (seed, res.K[0, 0])
        assert res.ok or res.corner_focal[2] > MAX_FOCAL_REL_STD * PICO[0], (seed, res.verdict, res.corner_focal)
        z.append(error / res.std["fx"])
        if seed == 3:
            assert res.model.period_spread and res.model.settled_period, res.model.fold_periods
            assert any("every fold choosing the period" in r for r in res.verdict), res.verdict
            assert not any("do not settle the wiggle's period" in r for r in res.verdict), res.verdict
    assert np.sum(np.abs(z) > 2) <= 1 and np.max(np.abs(z)) < 3, np.round(z, 2)


@pytest.mark.slow
def test_a_short_wiggle_of_a_low_resolution_sensor_states_honest_sigmas():
    """The issue's sigma honesty (the true fx within 2 stated sigmas in 90 % of trials) on the
    pico flexx class sensor, whose corners are detected (0.17 px RMS off their true places) and
    whose wiggle is short. The search's period is not settled on such views: it took 0.364 m for
    the true 0.468 in 8 of 64 seeds, fx 4.7 px off, stated to that period's +- 1.2 px. The whole
    calibration re-run on folds of the views, the period chosen again, states that (15 of these 16
    seeds within 2 sigmas, none trusted beyond 3; 13 of 16 before, one trusted 4.0 sigmas off);
    ``benchmarks/pico_honesty.py`` gives 64 seeds."""
    inside, trusted_far = 0, 0
    for seed in range(1, 17):
        board, views, _ = _pico(seed)
        res = calibrate(views, board)
        z = abs(res.K[0, 0] - PICO[0]) / res.std["fx"]
        inside += z <= 2
        trusted_far += bool(res.ok and z > 3)
    assert inside >= 15 and trusted_far == 0, (inside, trusted_far)


@pytest.mark.slow
def test_a_period_the_folds_of_the_views_do_not_settle_widens_fx_and_is_not_trusted():
    """Seed 61 of the pico flexx class sensor: the search takes a period 22 % short, fx about 5.8
    px low, stated +- 1.2 px and trusted before. Its folds choose other periods, and the stated
    sigma takes in their spread, which the corners alone (+- 1.4) leave it under: the truth within
    2 sigmas, and the result not trusted, the verdict asking for the modulation frequency. Told it,
    there is no period to choose and nothing is re-run."""
    board, views, _ = _pico(61)
    res = calibrate(views, board)
    error = res.K[0, 0] - PICO[0]
    assert abs(error) > 3, error   # the case this is about: a period the search got wrong
    assert abs(error) <= 2 * res.std["fx"] and res.std["fx"] > res.corner_focal[2], (error, res.std["fx"])
    assert not res.ok and any("period chosen again" in r for r in res.model.reasons), res.model.reasons
    assert res.model.period_spread["fx"] == res.std["fx"], res.model.period_spread
    assert len(res.model.fold_periods) == 5 and not res.model.settled_period, res.model.fold_periods
    assert any("do not settle the wiggle's period" in r for r in res.verdict), res.verdict
    assert any("fx is poorly constrained" in r and "modulation frequency" in r for r in res.verdict), res.verdict
    told = calibrate(views, board, modulation_hz=scenes.PICO_MODULATION_HZ)
    assert not any("period chosen again" in r for r in told.model.reasons), told.model.reasons
    assert not told.model.period_spread and not told.model.fold_periods


def test_a_near_frontal_wiggle_is_exact_on_noiseless_views():
    """Near frontal the corners cannot pin fx, and the depth's planes carry it. Planes fitted to
    depth corrected by the wiggle's own estimate shaped the observations they were fitted to, and
    on noiseless views the fit settled 1.7 % off, on a wrong offset and wiggle that agreed with
    those planes. The planes now keep the wiggle's planar part, which the fit predicts; what is
    left (0.2 % at worst) is the planes' own dependence on K, through the rays."""
    period = depth_bias.wiggle_period(20e6)
    for seed in range(3):
        phase = np.random.default_rng(seed).uniform(0, 2 * np.pi)
        noise = sim.Noise(depth=0.0, wiggle_amplitude=0.015, wiggle_period=period, wiggle_phase=phase)
        views = _views([F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0], 5, 16, seed, tilt=5.0, noise=noise,
                       corner_noise=0.0)
        res = calibrate(views, BOARD, modulation_hz=20e6)
        truth = 0.015 * np.array([np.cos(phase), np.sin(phase)])
        assert abs(res.K[0, 0] / F - 1) < 0.003, (seed, res.K[0, 0], res.depth_bias)
        assert np.hypot(*(res.depth_bias[4:6] - truth)) < 0.002 and abs(res.depth_bias[0]) < 0.003, res.depth_bias


@pytest.mark.slow
def test_a_near_frontal_wiggle_of_given_period_is_near_the_cramer_rao_bound():
    """Near frontal, a view's distance barely changes across the board, and its plane keeps only
    the wiggle's planar part, which trades with the focal length. The wiggle's curvature across
    each board does not: with it, the stated fx uncertainty is 1.4-3.9 times the least any
    unbiased method could have on these scenes (median 1.8; 2.0-5.6, median 3.3, from the planes
    alone), the errors stay within it (one of six at 2.1 sigmas), and they shrink to an RMS of
    1.3 px (2.4 from the planes; 0.9 with the plane's inliers cut about the plane, which biased
    quieter sensors: see test_a_near_frontal_wiggle_of_given_period_on_a_quiet_sensor...)."""
    lens = [F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0]
    camera = sim.SimCamera(np.asarray(lens, dtype=float), 200, 200)
    period = depth_bias.wiggle_period(20e6)
    ratios, errors, z = [], [], []
    for seed in range(6):
        phase = np.random.default_rng(seed).uniform(0, 2 * np.pi)
        noise = sim.Noise(depth=0.01, wiggle_amplitude=0.015, wiggle_period=period, wiggle_phase=phase)
        views = _views(lens, 5, 16, seed, tilt=5.0, noise=noise)
        res = calibrate(views, BOARD, modulation_hz=20e6)
        poses = sim.random_poses(camera, BOARD, 5, np.random.default_rng(seed), distance=(0.9, 1.4), max_tilt_deg=5.0)
        least = bound.Bound(bound.Scene(camera, BOARD, poses, views[0].ids, noise, 0.01)).covariance(
            list(range(8)), ["offset", "wiggle"])
        ratios.append(res.std["fx"] / np.sqrt(least[0, 0]))
        errors.append(res.K[0, 0] - F)
        z.append(errors[-1] / res.std["fx"])
        assert ratios[-1] > 0.9 and abs(z[-1]) < 3, (seed, res.K[0, 0], res.std["fx"])
    assert np.sum(np.abs(z) > 2) <= 1, z   # 2 sigmas: 95 % each, so 1 of 6 is no sign of a bias
    assert np.median(ratios) < 2.2, ratios
    assert np.sqrt(np.mean(np.square(errors))) < 1.5, errors


@pytest.mark.slow
def test_a_near_frontal_wiggle_of_given_period_on_a_quiet_sensor_is_within_its_sigmas():
    """With 2 mm of depth noise the stated fx uncertainty is a fifth of the benchmark's. A plane
    cut that kept one side of a bowed board's rim noise (planarize.on_surface), and each corner's
    wiggle placed at its depth with the wiggle's planar part still in it, biased the offset and
    fx by more than that: here 5 of 8 scenes lay beyond 2 stated sigmas, 4 beyond 3 (-6.5 at
    worst), all trusted. Now 1 beyond 3 (-3.7: that scene's fx spreads 1.4 times its stated
    sigma over draws of the noise, about a mean 1 sigma off; not traced)."""
    lens = [F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0]
    period = depth_bias.wiggle_period(20e6)
    z, errors = [], []
    for seed in range(8):
        phase = np.random.default_rng(100 + seed).uniform(0, 2 * np.pi)
        noise = sim.Noise(depth=0.002, wiggle_amplitude=0.015, wiggle_period=period, wiggle_phase=phase)
        res = calibrate(_views(lens, 7, 9, 100 + seed, tilt=5.0, noise=noise), BOARD, modulation_hz=20e6)
        z.append((res.K[0, 0] - F) / res.std["fx"])
        errors.append(res.K[0, 0] - F)
    z = np.abs(z)
    assert np.sum(z > 2) <= 2 and np.sum(z > 3) <= 1 and z.max() < 4.5, np.round(z, 2)
    assert np.sqrt(np.mean(np.square(errors))) < 0.6, np.round(errors, 2)


def _joints_views(monkeypatch, views: list[View], board: Board, **options) -> dict:
    """The views as the joint fit is given them (prepared, their plane samples, the board points),
    from calibrating ``views`` with ``options``."""
    seen = {}
    joint = model_choice.joint

    def spy(prepared, plane_samples, obj, *args):
        seen.update(prepared=prepared, samples=plane_samples, obj=obj)
        return joint(prepared, plane_samples, obj, *args)

    monkeypatch.setattr(model_choice, "joint", spy)
    calibrate(views, board, **options)
    return seen


def test_the_fits_depth_model_is_exact_at_the_true_parameters(monkeypatch):
    """On noiseless depth with 15 mm of wiggling, the corner depths the planes give and the fit's
    model of them agree at the true intrinsics, bias and poses: each corner's wiggle is placed on
    the plane of the depth without it. Placed on the fitted plane (which holds the wiggle's planar
    part) the model was 0.2-0.35 mm off, a depth error of the fit's own making that near frontal
    moved fx by up to 1 px."""
    from tof_calib_ros.core import bundle, view_planes
    lens = np.array([F, F, 99.5, 99.5, -0.3, 0.1, 1e-3, 1e-3, 0])
    camera = sim.SimCamera(lens, 200, 200)
    period, phase = depth_bias.wiggle_period(20e6), 5.57
    noise = sim.Noise(depth=1e-7, wiggle_amplitude=0.015, wiggle_period=period, wiggle_phase=phase)
    rng = np.random.default_rng(1)
    poses = sim.random_poses(camera, BOARD, 5, rng, distance=(0.9, 1.4), max_tilt_deg=5.0)
    ids = np.array([r * BOARD.cols + c for r in (0, 5, 10) for c in (0, 5, 10)])
    views = [View(f.depth, f.corners[ids], ids)
             for f in (sim.render(camera, BOARD, r, t, noise=noise, rng=rng) for r, t in poses)]
    seen = _joints_views(monkeypatch, views, BOARD, modulation_hz=20e6)
    intr = np.r_[lens[:8], 0.0]
    bias = np.r_[0, 0, 0, 0, 0.015 * np.cos(phase), 0.015 * np.sin(phase), 0]
    depths, floors, _, wiggles, radials = view_planes.planarize_all(seen["prepared"], seen["samples"], intr, bias,
                                                                    "z", period)
    obs = view_planes.view_observations(seen["obj"], seen["prepared"], depths, floors, wiggles, radials)
    truth = bundle.State(intr, bias, np.array([np.r_[np.ravel(r), np.ravel(t)] for r, t in poses]))
    problem = bundle.Problem(obs, "z", np.full(5, 0.01), np.full(5, 1e-3), [0, 1, 2, 3], None, period)
    _, ddep, _, _ = problem.raw(truth)
    assert np.max(np.abs(ddep)) < 2e-5, np.max(np.abs(ddep))


def test_the_wiggles_rows_read_the_true_wiggle_at_the_true_parameters(monkeypatch):
    """What the views' depth off their planes says of the wiggle (the fit's rows on its two terms)
    is centred on the true wiggle at the true parameters, on noiseless depth with 15 mm of a short
    wiggle over boards tilted up to 45 degrees. Read off the planes fitted with the wiggle in, it
    was 0.09 mm off here and 0.4 mm at the phase of ``_pico(16)``: a plane's depth is
    1 / (ray . coef), so the part of the wiggle it takes is not linear in the wiggle. There,
    without depth noise and with 0.12 px on the true corners, the fit followed the rows to fx
    1.3 and 1.2 px low in two draws (0.4 and 0.2 read off the planes fitted without it)."""
    from tof_calib_ros.core import view_planes
    camera = sim.SimCamera(PICO, 224, 171)
    period, phase = depth_bias.wiggle_period(80e6), 2.0
    noise = sim.Noise(depth=1e-7, offset=0.01, wiggle_amplitude=0.015, wiggle_period=period, wiggle_phase=phase)
    rng = np.random.default_rng(16)
    poses = sim.random_poses(camera, Board(5, 7, 0.03), 8, rng, distance=(0.25, 0.6), max_tilt_deg=45)
    frames = [sim.render(camera, Board(5, 7, 0.03), r, t, noise=noise, rng=rng) for r, t in poses]
    seen = _joints_views(monkeypatch, [View(f.depth, f.corners) for f in frames], Board(5, 7, 0.03), modulation_hz=80e6)
    wiggle = 0.015 * np.array([np.cos(phase), np.sin(phase)])
    bias = np.r_[0.01, 0, 0, 0, wiggle, 0]
    rows = view_planes.planarize_all(seen["prepared"], seen["samples"], PICO, bias, "z", period).wiggles
    read = np.linalg.solve(sum(w.information for w in rows), sum(w.moment for w in rows))
    assert np.all(np.abs(read - wiggle) < 2e-5), (read, wiggle)


def test_the_principal_point_counts_what_the_pixel_weights_choose():
    """Twenty views, every fourth quiet (0.01 px, against 0.1) and its corners 1 px to the right,
    as a detector's error on the nearest boards would put them (their scatter does not show it):
    weighted each by its own noise, cx follows the quiet views, 0.82 px off, stated +- 0.09 (4.5
    sigmas). Weighted alike the views' pixels move it beyond what their noise explains, the
    uncertainty includes the move (+- 0.55), and the result says so; without that error nothing
    is added."""
    stated = {}
    for moved in (0.0, 1.0):
        views = _views([F, F, 99.5, 99.5, 0, 0, 0, 0, 0], 20, 25, seed=2, corner_noise=0.0)
        rng = np.random.default_rng(2)
        for j, v in enumerate(views):
            quiet = j % 4 == 0
            corners = v.corners + rng.normal(0, 0.01 if quiet else 0.1, v.corners.shape) + [moved * quiet, 0.0]
            views[j] = View(v.depth, corners, v.ids)
        res = calibrate(views, BOARD)
        stated[moved] = res.std["cx"], res.noise_std["cx"]
        assert abs(res.K[0, 2] - 99.5) < 2 * res.std["cx"], (moved, res.K[0, 2], res.std["cx"])
        assert any("weighted alike" in r for r in res.model.reasons) == bool(moved), res.model.reasons
    assert stated[1.0][0] > 3 * stated[1.0][1], stated


def test_the_joints_mixing_lands_on_the_fixed_point_of_rounds_that_swing_or_crawl():
    """The joint fit's rounds map the K and bias the views were planarized with to the fit's. Where
    that map turns a move back on itself (few corners a view: fx swung between two values 4.7 px
    apart for 30 rounds) plain rounds never settle, and where it shrinks a move by little (0.6 a
    round on the pico flexx class sensor) they settle late; Anderson's mixing of three rounds
    lands on a linear map's fixed point in two free parameters, each in its own units, and leaves
    the held parameters where the fit put them."""
    turn = np.array([[-1.0, 0.0], [0.0, 0.6]])
    mix = np.array([[1.0, 1.0], [1.0, -1.0]]) / np.sqrt(2)
    slope, offset = mix @ turn @ mix.T, np.array([3.0, -2.0])
    free, std = np.array([0, 2]), np.array([0.5, 1.0, 0.002])

    def mapped(at: np.ndarray) -> np.ndarray:
        return np.r_[(offset + slope @ (at[free] / std[free])) * std[free], 7.0][[0, 2, 1]]

    fixed = np.linalg.solve(np.eye(2) - slope, offset) * std[free]
    at, rounds = np.array([1.0, 7.0, 0.01]), []
    for _ in range(3):
        rounds.append((at, mapped(at)))
        at = rounds[-1][1]
    mixed = model_choice._mixed(rounds, free, std[free], rounds[-1][1])
    assert np.allclose(mixed[free], fixed, rtol=0, atol=1e-9 * std[free]), (mixed, fixed)
    assert mixed[1] == 7.0
    plain = at
    for _ in range(50):
        plain = mapped(plain)
    assert np.max(np.abs(plain[free] - fixed) / std[free]) > 1, "plain rounds settle on this map"


def test_a_choice_started_from_a_larger_models_fit_estimates_or_drops_its_terms(monkeypatch):
    """The choice is made again from the state an earlier fit left (a wiggle found after the lens
    was chosen); it holds no term it does not estimate at that fit's value. A pinhole scene
    started where a fit in a strong lens and a depth tilt left off: with k3 held at -1.69, the
    choice took plumb_bob and a tilt the scene does not have to make up for it (paper_table's 4
    corners x 3 images with 15 mm of wiggling: fx 3.6 % off, 58 mm); dropped, the choice lands
    where it does from a clean start."""
    seen = {}
    select = model_choice.select_model

    def spy(observations, state, *args, **kwargs):
        seen.setdefault("args", (observations, state.copy(), *args))
        return select(observations, state, *args, **kwargs)

    monkeypatch.setattr(model_choice, "select_model", spy)
    calibrate(_views([F, F, 99.5, 99.5, 0, 0, 0, 0, 0], 4, 9, seed=3), BOARD)
    observations, clean, convention, options = seen["args"][:4]
    larger = clean.copy()
    larger.intrinsics[4:] = [-0.43, 1.04, 0.003, -0.01, -1.69] + [0.0] * (len(larger.intrinsics) - 9)
    larger.bias[depth_bias.TERMS["tilt"]] = [0.068, -0.018]
    got = {}
    for name, start in (("clean", clean), ("larger", larger)):
        state, free, model = select(observations, start, convention, options, lambda _m: None)
        held = np.setdiff1d(np.arange(4, len(state.globals_)), free)
        assert np.all(state.globals_[held] == 0), (name, model.distortion, model.depth_bias, state.globals_[held])
        got[name] = state.intrinsics[0]
    assert got["larger"] == pytest.approx(got["clean"], rel=1e-4) and got["clean"] == pytest.approx(F, rel=5e-3), got
