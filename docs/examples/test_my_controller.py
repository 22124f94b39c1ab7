"""My controller against a golden bag of the sorting line (the pytest plugin sorting_line_gym.testing)."""

from pathlib import Path

GOLDEN = Path(__file__).parent / "golden" / "basic_d"  # recorded with `sorting-line-bag record`
CONTROLLER = "sorting-line-controller --setup D --variant basic --agent rba"  # your controller's command


def test_answers_every_tick_as_recorded(sorting_line_check):
    verdict = sorting_line_check(GOLDEN, controller=CONTROLLER)  # open loop: the bag's ticks, one by one
    assert verdict.passed, verdict.summary()


def test_no_worse_than_recorded_in_closed_loop(sorting_line_check):
    verdict = sorting_line_check(GOLDEN, controller=CONTROLLER, closed_loop=True, max_reward_drop="5%")
    assert verdict.passed, verdict.summary()
