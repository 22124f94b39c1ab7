"""Record a golden bag of my controller driving a fresh line, then check it (sorting_line_gym.testing)."""

import subprocess

CONTROLLER = ["sorting-line-controller", "--setup", "D", "--variant", "basic", "--agent", "rba"]


def test_record_a_golden_bag_and_check_it(sorting_line_node, sorting_line_recorder, sorting_line_check, tmp_path):
    line = sorting_line_node(setup="D", variant="basic", seed=5, max_steps=20)  # lock-step, the test's namespace
    controller = subprocess.Popen([*CONTROLLER, "--ros-args", "-r", f"__ns:={line.namespace}"])
    try:
        recording = sorting_line_recorder(out=tmp_path / "golden")
        recording.wait_matched("cmd/speed")  # commands sent before the recorder matched them are not in the bag
        for seed in (5, None, 12):  # seeded resets, and one where the streams carry on
            assert line.run_episode(seed)[-1].truncated
        golden = recording.stop().path
    finally:
        controller.terminate()
        assert controller.wait(10) == 0
    verdict = sorting_line_check(golden, controller=" ".join(CONTROLLER))
    assert verdict.passed, verdict.summary()
