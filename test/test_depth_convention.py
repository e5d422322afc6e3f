"""The depth convention chosen by the boards' flatness: z, or the radial distance raw PMD sensors
give, recovered from sensors made to give each."""
import numpy as np
import pytest

from tof_calib_ros import Board, View, calibrate, sim
from tof_calib_ros.core.depth_convention import DECISIVE, ConventionEvidence

BOARD = Board(5, 7, 0.03)
CAMERA = sim.pmd_camera()
WRONG = {"z": "radial", "radial": "z"}


def _views(convention: str, seed: int, tilt: float, distance=(0.4, 1.0), n: int = 8) -> list[View]:
    """A ToF sensor with an offset and black squares read farther, giving ``convention`` depth."""
    rng = np.random.default_rng(seed)
    views = []
    for rvec, tvec in sim.random_poses(CAMERA, BOARD, n, rng, distance=distance, max_tilt_deg=tilt):
        f = sim.render(CAMERA, BOARD, rvec, tvec, convention=convention, rng=rng,
                       noise=sim.Noise(depth=0.005, offset=0.02, dark_offset=0.01))
        views.append(View(f.depth, f.corners + rng.normal(0, 0.05, f.corners.shape)))
    return views


@pytest.mark.parametrize("truth, tilt, seed", [
    ("z", 40, 1), ("radial", 40, 2),
    pytest.param("z", 5, 3, marks=pytest.mark.slow), pytest.param("radial", 5, 4, marks=pytest.mark.slow),
])
def test_the_convention_the_sensor_gives_is_chosen_and_calibrates_as_if_given(truth, tilt, seed):
    views = _views(truth, seed, tilt)
    auto = calibrate(views, BOARD)
    assert auto.options.depth_convention == "auto" and auto.depth_convention == truth
    assert any(r.startswith(f"depth convention {truth}: the boards are flat read as") for r in auto.model.reasons), \
        auto.model.reasons
    assert abs(auto.K[0, 0] - CAMERA.params[0]) <= 3 * auto.std["fx"] and auto.ok, auto.verdict
    # recorded where a file, a report's refits and `tof_calib check` read it
    assert auto.to_dict()["depth_convention"] == auto.to_dict()["model"]["depth_convention"] == truth
    assert auto.options.fixed(auto.model).depth_convention == truth
    # once chosen, the calibration is the one the convention given makes, to the last digit
    given = calibrate(views, BOARD, depth_convention=truth)
    np.testing.assert_array_equal(auto.K, given.K)
    assert not any("convention" in r for r in given.model.reasons), given.model.reasons
    # given wrong, it is said, and the result states what the bow costs (5 to 10 times the sigma)
    wrong = calibrate(views, BOARD, depth_convention=WRONG[truth])
    assert wrong.depth_convention == WRONG[truth]
    assert any(f"the depth looks like {'z-depth' if truth == 'z' else 'the radial distance'}" in r
               and "is the depth convention right?" in r for r in wrong.model.reasons), wrong.model.reasons
    assert wrong.std["fx"] > 4 * auto.std["fx"]


def test_boards_too_far_to_bow_leave_z_and_say_so():
    """At 2-2.5 m a 15x21 cm board spans too few rays for either reading to bow: z, ROS's
    convention, is taken and the reason says the data could not tell."""
    result = calibrate(_views("radial", 5, 40, distance=(2.0, 2.5)), BOARD)
    assert result.depth_convention == "z"
    assert any(r.startswith("depth convention z: the boards are about as flat") for r in result.model.reasons)


@pytest.mark.parametrize("statistic, read_as, chosen", [
    (2 * DECISIVE, "radial", "radial"), (-2 * DECISIVE, "z", "z"),
    (0.5 * DECISIVE, None, "z"), (-0.5 * DECISIVE, None, "z"),
])
def test_the_evidence_decides_beyond_its_threshold_only(statistic, read_as, chosen):
    evidence = ConventionEvidence(statistic, 6)
    assert evidence.read_as == read_as
    convention, why = evidence.choice()
    assert convention == chosen and ("about as flat" in why) == (read_as is None), why
    assert "over 6 views" in why
    # a convention given is doubted only where the evidence is decisive against it
    for given in ("z", "radial"):
        assert (evidence.doubt(given) is not None) == (read_as is not None and read_as != given)


def test_auto_with_the_radial_term_asks_for_z():
    """The radial term is an offset in the light's path of z-depth: with 'auto' the data might
    choose radial depth, where it means nothing, so it is refused before any work."""
    from tof_calib_ros import CalibrationError

    with pytest.raises(CalibrationError, match=r"the radial term is for z-depth \(depth_convention 'z'\)"):
        calibrate(_views("z", 1, 40, n=3), BOARD, depth_bias="offset+radial")
